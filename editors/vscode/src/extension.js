// The VS Code client: starts `swarmdsl lsp` (the command in the setting
// `swarmdsl.server.command`) for .swarm files and hands it the editor's requests.
// Everything the language knows lives in the server; this file only connects.
"use strict";
const vscode = require("vscode");
const { LanguageClient, TransportKind } = require("vscode-languageclient/node");

let client;

function serverOptions() {
  const words = vscode.workspace.getConfiguration("swarmdsl").get("server.command")
    || ["swarmdsl", "lsp"];
  const [command, ...args] = words;
  return { command, args, transport: TransportKind.stdio };
}

async function start(context) {
  client = new LanguageClient("swarmdsl", "swarmdsl", serverOptions(), {
    documentSelector: [{ scheme: "file", language: "swarm" },
                       { scheme: "untitled", language: "swarm" }],
  });
  try {
    await client.start();
  } catch (err) {
    vscode.window.showErrorMessage(
      `swarmdsl: could not start the language server (${err.message}). ` +
      "Install it with `pip install 'swarmdsl[lsp]'`, or set `swarmdsl.server.command`.");
  }
}

async function activate(context) {
  await start(context);
  context.subscriptions.push(vscode.workspace.onDidChangeConfiguration(async (event) => {
    if (event.affectsConfiguration("swarmdsl.server.command") && client) {
      await client.stop();
      await start(context);
    }
  }));
}

async function deactivate() {
  if (client) {
    await client.stop();
  }
}

module.exports = { activate, deactivate };
