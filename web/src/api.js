// Calls to the service's /v1 API, with the API token the user entered (kept
// in the browser's local storage); without one, none is sent (a server
// started with --no-auth).

const KEY = "impostor-token";

export function token() {
  return localStorage.getItem(KEY) || "";
}

export function setToken(value) {
  if (value) localStorage.setItem(KEY, value);
  else localStorage.removeItem(KEY);
}

function headers(extra = {}) {
  const t = token();
  return t ? { ...extra, Authorization: `Bearer ${t}` } : extra;
}

/// A response that is not 2xx as an Error carrying the service's message.
async function check(res, path) {
  if (res.ok) return res;
  let msg = `${res.status} ${res.statusText}`;
  try {
    const body = await res.json();
    if (body && body.error) msg = `${res.status}: ${body.error}`;
  } catch {
    // not JSON: keep the status
  }
  const err = new Error(`${path}: ${msg}`);
  err.status = res.status;
  throw err;
}

export async function request(path, init = {}) {
  const res = await fetch(path, { ...init, headers: headers(init.headers) });
  return check(res, path);
}

export async function json(path, init) {
  return (await request(path, init)).json();
}

export async function bytes(path) {
  return (await request(path)).arrayBuffer();
}

export async function blobUrl(path) {
  return URL.createObjectURL(await (await request(path)).blob());
}

/// Follows the job's server-sent events (GET /v1/jobs/{id}/events), read
/// with fetch so that the token can be sent; calls `onStatus` with each
/// status event. Resolves when the stream ends (after the final state).
export async function followEvents(id, onStatus, signal) {
  const res = await request(`/v1/jobs/${id}/events`, { signal });
  const reader = res.body.pipeThrough(new TextDecoderStream()).getReader();
  let buf = "";
  for (;;) {
    const { value, done } = await reader.read();
    if (done) return;
    buf += value;
    let end;
    while ((end = buf.indexOf("\n\n")) >= 0) {
      const block = buf.slice(0, end);
      buf = buf.slice(end + 2);
      let event = "message";
      const data = [];
      for (const line of block.split("\n")) {
        if (line.startsWith("event:")) event = line.slice(6).trim();
        else if (line.startsWith("data:")) data.push(line.slice(5).trimStart());
      }
      if (event === "status" && data.length) onStatus(JSON.parse(data.join("\n")));
    }
  }
}
