// The studio's HTTP API (docs/studio.md): every call is relative to the page, carries the token when the studio
// was opened with one, and turns an error answer into an Error whose message a teacher can read.

const TOKEN_KEY = "beastbt_studio_token";

/** The token of a studio served off loopback: read once from the address, then kept for this tab only. */
export const token: string | null = (() => {
  const params = new URLSearchParams(location.search);
  const given = params.get("token");
  if (given) {
    try { sessionStorage.setItem(TOKEN_KEY, given); } catch { /* storage off: the cookie carries it */ }
    params.delete("token");
    const rest = params.toString();
    history.replaceState(null, "", location.pathname + (rest ? "?" + rest : "") + location.hash);
    return given;
  }
  try { return sessionStorage.getItem(TOKEN_KEY); } catch { return null; }
})();

/** An address of the studio's server with the token added (for fetch, and for the console's iframe). */
export function withToken(path: string): string {
  return token ? path + (path.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(token) : path;
}

/** An answer other than 2xx: its status and its JSON body (the 409 of a save carries disk_text). */
export class ApiError extends Error {
  constructor(message: string, public status: number, public body: any) { super(message); }
}

/** Call the API: GET without a body, else the method given (POST by default) with a JSON body. */
export async function api<T = any>(path: string, body?: unknown, method?: string): Promise<T> {
  const init: RequestInit = { method: method ?? (body === undefined ? "GET" : "POST"), headers: {} };
  if (body !== undefined) {
    init.body = JSON.stringify(body);
    (init.headers as Record<string, string>)["Content-Type"] = "application/json";
  }
  const response = await fetch(withToken("api/" + path), init);
  const text = await response.text();
  let data: any = null;
  try { data = text ? JSON.parse(text) : null; } catch { data = text; }
  if (!response.ok) {
    const message = (data && typeof data === "object" && (data.error || data.message)) || text || response.statusText;
    throw new ApiError(String(message), response.status, data);
  }
  return data as T;
}

/** The path of a file in the API's address: each segment escaped, the slashes kept. */
export function filePath(path: string): string {
  return path.split("/").map(encodeURIComponent).join("/");
}
