// Starts `arbor lsp` for .sl and .rib documents (the grammars come from package.json).
const vscode = require("vscode");
const { LanguageClient } = require("vscode-languageclient/node");

let client;

function activate(context) {
  const cfg = vscode.workspace.getConfiguration("arbor");
  const command = cfg.get("path", "arbor");
  const args = ["lsp", ...cfg.get("args", [])];
  client = new LanguageClient(
    "arbor",
    "arbor",
    { run: { command, args }, debug: { command, args } },
    { documentSelector: [{ scheme: "file", language: "rsl" }, { scheme: "file", language: "rib" }] }
  );
  context.subscriptions.push({ dispose: () => client && client.stop() });
  return client.start();
}

function deactivate() {
  return client ? client.stop() : undefined;
}

module.exports = { activate, deactivate };
