// Monaco's ESM files carry no types of their own but editor.api's; elkjs's api module has its own.
declare module "monaco-editor/esm/vs/editor/editor.api.js" {
  export * from "monaco-editor/esm/vs/editor/editor.api";
}
declare module "monaco-editor/esm/*";
declare module "*.css";
