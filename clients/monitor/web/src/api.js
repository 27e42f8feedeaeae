// The bridge's HTTP API (clients/monitor/README.md): JSON in and out, the session cookie sent
// by the browser itself (HttpOnly: this code never sees it).

/// GET `path`; resolves to the parsed JSON or throws an Error carrying the server's sentence.
export async function getJson(path) {
  const response = await fetch(path, { credentials: 'same-origin', cache: 'no-store' });
  const body = await response.json().catch(() => ({}));
  if (!response.ok) throw apiError(response.status, body);
  return body;
}

/// POST `body` as JSON to `path`. Resolves to {ok, status, body}; never throws for an HTTP
/// error (the page shows body.error), only for a network failure.
export async function post(path, body = {}) {
  const response = await fetch(path, {
    method: 'POST',
    credentials: 'same-origin',
    headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify(body),
  });
  const parsed = await response.json().catch(() => ({ error: `HTTP ${response.status}` }));
  return { ok: response.ok, status: response.status, body: parsed };
}

function apiError(status, body) {
  const e = new Error(body && body.error ? body.error : `HTTP ${status}`);
  e.status = status;
  return e;
}
