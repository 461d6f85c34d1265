// The editor pane: Monaco with monaco-yaml (completion, hover and schema errors from our JSON Schemas) and
// beastbt's own problems as markers. Map edits come in as text and go through executeEdits, so one undo stack
// covers typing and map clicks alike.
import * as monaco from "./monaco-core";
import { configureMonacoYaml, type MonacoYaml } from "monaco-yaml";

export { monaco };

// The workers are files of the page itself (no CDN, no blob: URL): they load offline from the package.
(self as any).MonacoEnvironment = {
  getWorkerUrl(_moduleId: string, label: string): string {
    return label === "yaml" ? "yaml.worker.js" : "editor.worker.js";
  },
};

/** One problem of beastbt's validation (docs/studio.md): 1-based line and column. */
export interface Problem {
  severity: string;
  line: number;
  column: number;
  end_line?: number;
  end_column?: number;
  message: string;
  hint?: string;
  code?: string;
}

let yaml: MonacoYaml | null = null;
const schemaCache = new Map<string, unknown>();

/** The editor, in `host`: YAML, two-space indentation, no minimap (a mission is a page or two). */
export function createEditor(host: HTMLElement): monaco.editor.IStandaloneCodeEditor {
  yaml = configureMonacoYaml(monaco as any, {
    enableSchemaRequest: true,
    hover: true,
    completion: true,
    validate: true,
    format: false,
    schemas: [],
  });
  return monaco.editor.create(host, {
    language: "yaml",
    automaticLayout: true,
    minimap: { enabled: false },
    tabSize: 2,
    insertSpaces: true,
    fontSize: 14,
    scrollBeyondLastLine: false,
    renderWhitespace: "boundary",
    wordWrap: "on",
    theme: "vs",
    quickSuggestions: { other: true, comments: false, strings: true },
    fixedOverflowWidgets: true,
  });
}

/** Tell monaco-yaml which schema drives the model at `uri` (`schemaUrl` absolute: its `$ref`s resolve beside it). */
export async function useSchema(uri: monaco.Uri, schemaUrl: string | null): Promise<void> {
  if (!yaml) return;
  if (!schemaUrl) {
    yaml.update({ schemas: [] });
    return;
  }
  let schema = schemaCache.get(schemaUrl);
  if (schema === undefined) {
    try {
      const response = await fetch(schemaUrl);
      schema = response.ok ? await response.json() : null;
    } catch {
      schema = null;
    }
    schemaCache.set(schemaUrl, schema);
  }
  yaml.update({
    enableSchemaRequest: true,
    schemas: schema ? [{ uri: schemaUrl, fileMatch: [uri.toString()], schema: schema as any }] : [],
  });
}

/**
 * Replace the model's text by `text` as one undoable edit touching only what changed (the common head and tail
 * are kept), so the cursor, the folding and the scroll stay where they were.
 */
export function replaceText(editor: monaco.editor.IStandaloneCodeEditor, text: string, source: string): void {
  const model = editor.getModel();
  if (!model) return;
  const old = model.getValue();
  if (old === text) return;
  let head = 0;
  const max = Math.min(old.length, text.length);
  while (head < max && old.charCodeAt(head) === text.charCodeAt(head)) head++;
  let tail = 0;
  while (tail < max - head && old.charCodeAt(old.length - 1 - tail) === text.charCodeAt(text.length - 1 - tail)) {
    tail++;
  }
  const start = model.getPositionAt(head);
  const end = model.getPositionAt(old.length - tail);
  const inserted = text.slice(head, text.length - tail);
  editor.pushUndoStop();
  editor.executeEdits(source, [{
    range: new monaco.Range(start.lineNumber, start.column, end.lineNumber, end.column),
    text: inserted,
    forceMoveMarkers: true,
  }]);
  editor.pushUndoStop();
  const shown = model.getPositionAt(head + inserted.length);
  editor.revealLineInCenterIfOutsideViewport(shown.lineNumber);
}

const SEVERITY: Record<string, monaco.MarkerSeverity> = {
  error: monaco.MarkerSeverity.Error,
  warning: monaco.MarkerSeverity.Warning,
  info: monaco.MarkerSeverity.Info,
  hint: monaco.MarkerSeverity.Hint,
};

/** Show beastbt's problems as markers (owner "beastbt": monaco-yaml's own stay beside them). */
export function showMarkers(model: monaco.editor.ITextModel, problems: Problem[]): void {
  monaco.editor.setModelMarkers(model, "beastbt", problems.map((p) => {
    const line = Math.max(1, Math.min(p.line || 1, model.getLineCount()));
    const column = Math.max(1, p.column || 1);
    let endLine = p.end_line ?? line;
    let endColumn = p.end_column ?? 0;
    if (endColumn <= column && endLine === line) {
      // No end given: mark the word at the position (or to the end of the line).
      const word = model.getWordAtPosition({ lineNumber: line, column });
      endColumn = word ? word.endColumn : model.getLineMaxColumn(line);
      endLine = line;
    }
    return {
      severity: SEVERITY[p.severity] ?? monaco.MarkerSeverity.Error,
      message: p.hint ? `${p.message}\nhint: ${p.hint}` : p.message,
      source: "beastbt",
      code: p.code,
      startLineNumber: line,
      startColumn: column,
      endLineNumber: endLine,
      endColumn: Math.max(endColumn, column + 1),
    };
  }));
}

/** Select `line` (1-based) from `column` to its end (or to end_line/end_column), show it and focus the editor. */
export function selectAt(editor: monaco.editor.IStandaloneCodeEditor, line: number, column = 1,
                         endLine?: number, endColumn?: number): void {
  const model = editor.getModel();
  if (!model) return;
  const l = Math.max(1, Math.min(line, model.getLineCount()));
  const el = Math.max(l, Math.min(endLine ?? l, model.getLineCount()));
  const ec = endColumn ?? model.getLineMaxColumn(el);
  const c = Math.max(1, Math.min(column, model.getLineMaxColumn(l)));
  const selection = new monaco.Selection(l, c, el, Math.max(ec, el === l ? c : 1));
  editor.setSelection(selection);
  editor.revealRangeInCenterIfOutsideViewport(selection);
  editor.focus();
}
