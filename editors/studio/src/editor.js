// The studio's editor: CodeMirror 6 in place of the page's <textarea id="source">, with
// highlighting from the VS Code extension's TextMate grammar (the same patterns, so the
// two cannot drift) and diagnostics, hover, completion, rename, definition and
// formatting from `swarmdsl lsp` over the studio's websocket `/lsp` (token-gated).
//
// The textarea stays the page's model: its `value`, `focus`, `setSelectionRange` and
// `selectionStart` now read and move the editor, and an edit fires its `input` event,
// so the page's own code (checks, run, save, the diagnostics list) works unchanged.
//
// Built by `npm run build` in editors/studio into swarmdsl/studio/static/editor.js.
import { EditorView, keymap, lineNumbers, highlightActiveLine, drawSelection }
  from "@codemirror/view";
import { EditorState } from "@codemirror/state";
import { defaultKeymap, history, historyKeymap } from "@codemirror/commands";
import { StreamLanguage, syntaxHighlighting, bracketMatching, indentOnInput }
  from "@codemirror/language";
import { tagHighlighter, tags } from "@lezer/highlight";
import { closeBrackets, closeBracketsKeymap, completionKeymap } from "@codemirror/autocomplete";
import { LSPClient, LSPPlugin, languageServerExtensions } from "@codemirror/lsp-client";
import grammar from "../../vscode/syntaxes/swarm.tmLanguage.json";

// ---- highlighting: the TextMate grammar's patterns, as a stream tokenizer ----
const SCOPE_TOKEN = [
  ["comment", "comment"], ["string", "string"], ["variable.other.member", "swarmMember"],
  ["constant.numeric", "number"], ["constant.language", "swarmBool"],
  ["keyword.operator.word", "keyword"], ["keyword.control", "keyword"],
  ["support.function", "swarmBuiltin"], ["entity.name.function", "swarmFunction"],
  ["variable.language", "swarmState"], ["constant.other", "swarmConstant"],
  ["keyword.operator", "operator"],
];

function patterns() {
  const out = [];
  const add = (rule) => {
    if (rule.patterns) { rule.patterns.forEach(add); return; }
    if (!rule.match || !rule.name) return;
    const token = SCOPE_TOKEN.find(([scope]) => rule.name.startsWith(scope));
    if (token) out.push([new RegExp(rule.match, "y"), token[1]]);
  };
  for (const name of ["comment", "string", "member", "number", "literal", "keyword",
                      "call", "state", "operator"]) {
    add(grammar.repository[name]);
  }
  return out;
}

const PATTERNS = patterns();
const highlighter = tagHighlighter([
  { tag: tags.keyword, class: "tok-keyword" }, { tag: tags.comment, class: "tok-comment" },
  { tag: tags.string, class: "tok-string" }, { tag: tags.number, class: "tok-number" },
  { tag: tags.bool, class: "tok-bool" }, { tag: tags.operator, class: "tok-operator" },
  { tag: tags.propertyName, class: "tok-member" },
  { tag: tags.standard(tags.function(tags.variableName)), class: "tok-builtin" },
  { tag: tags.function(tags.variableName), class: "tok-function" },
  { tag: tags.special(tags.variableName), class: "tok-state" },
  { tag: tags.constant(tags.variableName), class: "tok-constant" },
  { tag: tags.variableName, class: "tok-name" },
]);
const swarm = StreamLanguage.define({
  name: "swarm",
  token(stream) {
    if (stream.eatSpace()) return null;
    for (const [regex, token] of PATTERNS) {
      regex.lastIndex = stream.pos;
      const m = regex.exec(stream.string);
      if (m && m[0].length) {
        stream.pos += m[0].length;
        return token;
      }
    }
    if (stream.match(/^[A-Za-z_][A-Za-z0-9_]*/)) return "swarmName";
    stream.next();
    return null;
  },
  // names of their own: the stream parser's legacy names ("builtin"...) would win
  tokenTable: {
    swarmMember: tags.propertyName, swarmBool: tags.bool,
    swarmBuiltin: tags.standard(tags.function(tags.variableName)),
    swarmFunction: tags.function(tags.variableName),
    swarmState: tags.special(tags.variableName),
    swarmConstant: tags.constant(tags.variableName), swarmName: tags.variableName,
  },
  languageData: { commentTokens: { line: "#" } },
});

// ---- the language server over a websocket ----
function socketTransport(url) {
  const handlers = new Set();
  let queue = [];
  const ws = new WebSocket(url);
  ws.onmessage = (event) => {
    for (const handler of handlers) handler(event.data);
  };
  ws.onopen = () => {
    for (const message of queue) ws.send(message);
    queue = [];
  };
  return {
    send(message) {
      if (ws.readyState === WebSocket.OPEN) ws.send(message);
      else if (ws.readyState === WebSocket.CONNECTING) queue.push(message);
      else throw new Error("the language server's connection is closed");
    },
    subscribe(handler) { handlers.add(handler); },
    unsubscribe(handler) { handlers.delete(handler); },
    socket: ws,
  };
}

// ---- the editor in place of the textarea ----
export function attach(textarea, { url, uri, onRun, onSave }) {
  const initial = textarea.value;
  let quiet = false;         // a change the page made: no `input` event for it
  const transport = socketTransport(url);
  const client = new LSPClient({ extensions: languageServerExtensions(), timeout: 10000 })
    .connect(transport);
  const view = new EditorView({
    parent: textarea.parentNode,
    state: EditorState.create({
      doc: initial,
      extensions: [
        lineNumbers(), history(), drawSelection(), highlightActiveLine(), bracketMatching(),
        closeBrackets(), indentOnInput(), swarm, syntaxHighlighting(highlighter),
        EditorState.tabSize.of(2),
        keymap.of([
          { key: "Mod-Enter", run: () => { onRun(); return true; } },
          { key: "Mod-s", run: () => { onSave(); return true; }, preventDefault: true },
          { key: "Tab", run: (v) => { v.dispatch(v.state.replaceSelection("  ")); return true; } },
          ...closeBracketsKeymap, ...completionKeymap, ...historyKeymap, ...defaultKeymap,
        ]),
        LSPPlugin.create(client, uri, "swarm"),
        EditorView.updateListener.of((update) => {
          if (!update.docChanged) return;
          mirror();
          if (!quiet) textarea.dispatchEvent(new Event("input"));
        }),
      ],
    }),
  });
  view.dom.id = "code";
  textarea.style.display = "none";
  // the viewer's keys (space, `.`, `f`...) are for the page, not while typing here
  view.dom.addEventListener("keydown", (event) => event.stopPropagation());

  // the textarea's own value follows the text too, for what reads it directly (a test
  // harness's isolated world does not see the properties defined below)
  const nativeValue = Object.getOwnPropertyDescriptor(HTMLTextAreaElement.prototype, "value");
  const mirror = () => nativeValue.set.call(textarea, view.state.doc.toString());
  const offsetOf = (n) => Math.max(0, Math.min(n, view.state.doc.length));
  Object.defineProperties(textarea, {
    value: {
      configurable: true,
      get: () => view.state.doc.toString(),
      set: (text) => {
        if (text === view.state.doc.toString()) return;
        quiet = true;
        try {
          view.dispatch({ changes: { from: 0, to: view.state.doc.length, insert: text } });
        } finally {
          quiet = false;
        }
      },
    },
    selectionStart: { configurable: true, get: () => view.state.selection.main.from },
    selectionEnd: { configurable: true, get: () => view.state.selection.main.to },
    scrollTop: { configurable: true, get: () => view.scrollDOM.scrollTop, set: () => {} },
  });
  textarea.focus = () => view.focus();
  textarea.setSelectionRange = (from, to) => view.dispatch({
    selection: { anchor: offsetOf(from), head: offsetOf(to) }, scrollIntoView: true });
  return { view, client, transport };
}
