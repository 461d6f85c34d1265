// Installed before monaco-yaml's worker starts: see yaml-worker.ts.
const pageFetch = self.fetch.bind(self);
const SCHEMA = /^file:\/\/.*?\/schemas\/((?:parts\/)?[\w.-]+\.schema\.json)(?:#.*)?$/;

self.fetch = (input: RequestInfo | URL, init?: RequestInit): Promise<Response> => {
  const url = input instanceof Request ? input.url : String(input);
  const m = SCHEMA.exec(url);
  return pageFetch(m ? new URL(`schemas/${m[1]}`, self.location.href).href : input, init);
};
