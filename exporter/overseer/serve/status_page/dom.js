// Shared by every view: building DOM nodes from text (never from HTML), levels and their order, times.
// Robot text is hostile: it only ever reaches the page as text nodes or attribute values.

export const STATES = ["ERROR", "WARN", "STALE", "OK"];  // worst first: ERROR > WARN > STALE > OK
const RANK = {OK: 0, STALE: 1, WARN: 2, ERROR: 3};

/** A new element with attributes (set as values, never parsed) and children (strings become text). */
export function element(tag, attributes, ...children) {
  const node = document.createElement(tag);
  for (const [name, value] of Object.entries(attributes || {})) {
    if (value !== undefined && value !== null && value !== false) node.setAttribute(name, value === true ? "" : value);
  }
  for (const child of children) {
    if (child !== undefined && child !== null) node.append(child);
  }
  return node;
}

/** A coloured level badge. */
export function badge(state) {
  return element("span", {class: `badge ${state}`, "data-state": state}, state);
}

/** The severity rank of a state name (higher is worse); unknown names rank as OK. */
export function rank(state) {
  return RANK[state] ?? 0;
}

/** The worst of some state names by severity (not the numeric maximum); OK when there are none. */
export function worstState(states) {
  let worst = "OK";
  for (const state of states) if (rank(state) > rank(worst)) worst = state;
  return worst;
}

/** A unix time as local date and time, or "never". */
export function timeText(seconds) {
  return seconds === null || seconds === undefined ? "never" : new Date(seconds * 1000).toLocaleString();
}

/** How long ago a unix time was, relative to `now` (unix seconds). */
export function agoText(seconds, now) {
  if (seconds === null || seconds === undefined) return "never";
  return `${durationText(now - seconds)} ago`;
}

/** A duration in seconds as "42 s", "12 min" or "3 h". */
export function durationText(seconds) {
  const age = Math.max(0, Math.round(seconds));
  if (age < 120) return `${age} s`;
  if (age < 7200) return `${Math.round(age / 60)} min`;
  return `${Math.round(age / 3600)} h`;
}

/** GET a JSON document of the exporter; rejects with an Error carrying `status` on an HTTP error. */
export async function getJson(path) {
  const response = await fetch(path, {cache: "no-store"});
  if (!response.ok) {
    const error = new Error(`${path}: HTTP ${response.status}`);
    error.status = response.status;
    throw error;
  }
  return response.json();
}

/** Send a JSON `body` (or none) with `method`; the answer's JSON, or an Error with the exporter's reason. */
export async function sendJson(method, path, body) {
  const init = {method, cache: "no-store", headers: {}};
  if (body !== undefined) {
    init.headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  const response = await fetch(path, init);
  const answer = await response.json().catch(() => ({}));
  if (!response.ok) {
    const error = new Error(answer.error || `${path}: HTTP ${response.status}`);
    error.status = response.status;
    throw error;
  }
  return answer;
}
