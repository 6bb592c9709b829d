// swarmdsl studio, the page: the editor with the checker's diagnostics as you type,
// run / save / export, and the websocket to the server (reconnecting when it drops).
"use strict";

const token = new URLSearchParams(location.search).get("token") || "";
const $ = id => document.getElementById(id);
const source = $("source"), gutter = $("gutter"), diagnosticsBox = $("diagnostics");
const CHECK_DELAY = 300;       // ms after the last key before the text is checked

let socket = null;
let retry = 250;
const transport = {
  send(obj) {
    if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(obj));
  },
};
const core = new StudioCore($("studio"), transport);
// CodeMirror on the language server in place of the textarea (editor.js), which keeps
// the textarea as the model this page reads and writes
if (window.SwarmEditor) {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  window.editor = SwarmEditor.attach(source, {
    url: `${scheme}://${location.host}/lsp?token=${encodeURIComponent(token)}`,
    uri: document.body.dataset.uri, onRun: () => runText(), onSave: () => save(),
  });
  gutter.style.display = "none";
}
window.studio = core;          // for tests and the benchmark

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  socket = new WebSocket(`${scheme}://${location.host}/ws?token=${encodeURIComponent(token)}`);
  socket.binaryType = "arraybuffer";
  socket.onopen = () => {
    retry = 250;
    $("connection").textContent = "connected";
    $("connection").className = "";
    core.hello();
  };
  socket.onmessage = event => {
    if (typeof event.data === "string") core.onText(JSON.parse(event.data));
    else core.onFrame(event.data);
  };
  socket.onclose = () => {
    $("connection").textContent = "connection lost: retrying…";
    $("connection").className = "lost";
    setTimeout(connect, retry);
    retry = Math.min(retry * 2, 4000);
  };
}

// ---- the editor ----
let shownDraft = null;         // the editor's text as the server last had it
let savedText = null;          // the file on disk, as last known (null: unreadable)
let checkTimer = null;
let lastDiagnostics = [];

function markUnsaved() {       // unsaved: the editor's text is not the file's
  const unsaved = savedText === null || source.value !== savedText;
  $("unsaved").hidden = !unsaved;
  document.title = `${unsaved ? "● " : ""}${$("file-name").textContent} · swarmdsl studio`;
}

function renumber() {
  const lines = source.value.split("\n").length;
  if (gutter.childElementCount !== lines) {
    gutter.innerHTML = "";
    for (let i = 1; i <= lines; i++) {
      const d = document.createElement("div");
      d.textContent = i;
      d.dataset.line = i;
      gutter.append(d);
    }
  }
  markLines(lastDiagnostics);
  gutter.scrollTop = source.scrollTop;
}

function markLines(found) {
  for (const d of gutter.children) { d.className = ""; d.title = ""; }
  for (const d of found) {
    const row = d.line && gutter.children[d.line - 1];
    if (row && row.className !== "error") {
      row.className = d.severity === "warning" ? "warning" : "error";
      row.title = d.message + (d.hint ? "\nhint: " + d.hint : "");
    }
  }
}

function showDiagnostics(found) {
  lastDiagnostics = found;
  diagnosticsBox.innerHTML = "";
  for (const d of found) {
    const row = document.createElement("div");
    row.className = d.severity === "warning" ? "warning" : "error";
    const where = d.line ? `${d.line}:${d.col}: ` : "";
    row.textContent = `${where}${d.severity}: ${d.message}` + (d.hint ? `\n  hint: ${d.hint}` : "");
    row.dataset.line = d.line || "";
    row.addEventListener("click", () => d.line && goTo(d.line, d.col));
    diagnosticsBox.append(row);
  }
  markLines(found);
}

function goTo(line, col) {
  const lines = source.value.split("\n");
  let offset = 0;
  for (let i = 0; i < line - 1 && i < lines.length; i++) offset += lines[i].length + 1;
  offset += Math.max(0, (col || 1) - 1);
  source.focus();
  source.setSelectionRange(offset, offset);
}

async function post(path, body) {
  const response = await fetch(`${path}?token=${encodeURIComponent(token)}`, {
    method: "POST", headers: {"content-type": "application/json"}, body: JSON.stringify(body),
  });
  const data = await response.json();
  if (!response.ok) throw new Error(data.error || response.statusText);
  return data;
}

async function check() {
  const text = source.value;
  try {
    const data = await post("api/check", {text});
    if (source.value === text) showDiagnostics(data.diagnostics);
  } catch (err) {
    say(`check failed: ${err.message}`, true);
  }
}

function say(text, bad) {
  $("message").textContent = text;
  $("message").style.color = bad ? "#ff8f8f" : "#9ad29a";
}

source.addEventListener("input", () => {
  renumber();
  markUnsaved();
  clearTimeout(checkTimer);
  checkTimer = setTimeout(check, CHECK_DELAY);
});
source.addEventListener("scroll", () => { gutter.scrollTop = source.scrollTop; });
source.addEventListener("keydown", e => {
  if (e.key === "Tab") {
    e.preventDefault();
    source.setRangeText("  ", source.selectionStart, source.selectionEnd, "end");
    source.dispatchEvent(new Event("input"));
  } else if ((e.ctrlKey || e.metaKey) && e.key === "Enter") {
    e.preventDefault();
    runText();
  } else if ((e.ctrlKey || e.metaKey) && e.key === "s") {
    e.preventDefault();
    save();
  }
});

function runText() {
  say("compiling…");
  transport.send({op: "run", text: source.value});
}

async function save() {
  const text = source.value;
  try {
    const data = await post("api/save", {text});
    savedText = text;
    markUnsaved();
    say(`saved ${data.saved}`);
  } catch (err) {
    say(err.message, true);
  }
}

async function exportRun() {
  const video = $("export-video").value || null;
  say("exporting: replaying the run…");
  try {
    const data = await post("api/export", {video});
    let text = `exported ${data.ticks} ticks to ${data.folder}: ${data.files.join(", ")}`;
    if (data.note) text += `\n${data.note}`;
    if (data.video_error) text += `\nno video: ${data.video_error}`;
    if (data.fault) text += `\n${data.fault}`;
    say(text, !!(data.fault || data.video_error));
  } catch (err) {
    say(`export failed: ${err.message}`, true);
  }
}

function reload() {
  if (!$("unsaved").hidden && !confirm("Drop the unsaved edits and read the file again?")) return;
  say("reloading…");
  transport.send({op: "reload"});
}

$("run").addEventListener("click", runText);
$("save").addEventListener("click", save);
$("reload").addEventListener("click", reload);
$("export").addEventListener("click", exportRun);

core.onScene = scene => {
  $("file-name").textContent = scene.file;
  if (shownDraft === null || (scene.draft !== shownDraft && source.value === shownDraft)) {
    source.value = scene.draft;         // the first scene, or a text from elsewhere
    renumber();
  }
  shownDraft = scene.draft;
  savedText = scene.saved;
  markUnsaved();
  // the scene's diagnostics are those of its draft: shown only beside that text; a
  // text typed since is checked afresh
  if (source.value === scene.draft) {
    showDiagnostics(scene.errors && scene.errors.length ? scene.errors : scene.warnings || []);
  } else {
    clearTimeout(checkTimer);
    checkTimer = setTimeout(check, CHECK_DELAY);
  }
  fitCanvas();
};
core.onResult = msg => {
  if (msg.op === "reload" && typeof msg.text === "string") {
    source.value = shownDraft = msg.text;
    renumber();
    markUnsaved();
    showDiagnostics(msg.errors);
    say(msg.errors.length ? "reloaded: the file has errors (the last good run goes on)"
                          : "reloaded the file", msg.errors.length > 0);
  }
  if (msg.op === "run") {
    if (msg.errors.length) {
      showDiagnostics(msg.errors);
      say("not run: the program has errors (the last good run goes on)", true);
    } else {
      say("running the new text");
    }
  }
};

function fitCanvas() {
  const scene = core.scene;
  if (!scene || !scene.world) return;
  const box = core.viewBox;
  const width = Math.max(200, box.clientWidth - 12);
  const height = Math.max(150, window.innerHeight - 90);
  const [ww, wh] = scene.world;
  const s = Math.min(width / ww, height / wh);
  const w = Math.round(ww * s), h = Math.round(wh * s);
  if (core.canvas.width !== w || core.canvas.height !== h) {
    core.canvas.width = w;
    core.canvas.height = h;
    core.canvas.style.width = w + "px";
    if (core.frame) core.renderer.draw(core.frame, core.opts);
  }
}
window.addEventListener("resize", fitCanvas);
document.addEventListener("keydown", e => {
  const typing = ["TEXTAREA", "INPUT", "SELECT"].includes(document.activeElement.tagName);
  if (typing || e.ctrlKey || e.metaKey || e.altKey) return;
  if (core.key(e)) e.preventDefault();
});

connect();
