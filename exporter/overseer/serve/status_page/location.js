// The page's state lives in its URL, so that every view has a deep link an alert can point at:
//   fleet view  ?level=ERROR,WARN&q=TEXT&sort=KEY
//   robot view  ?robot=<percent-encoded robot name>   (names may contain "/")
//               &component=<name>   its timeline narrowed to components whose name contains this

import {STATES} from "./dom.js";

export const SORTS = ["name", "level", "errors", "last_message"];

/** The view a URL's query asks for: {robot, component, levels (a Set of state names), q, sort}. */
export function readQuery(search) {
  const params = new URLSearchParams(search);
  const levels = new Set();
  for (const value of params.getAll("level")) {
    for (const word of value.split(",")) {
      const state = word.trim().toUpperCase();
      if (STATES.includes(state)) levels.add(state);
    }
  }
  const sort = params.get("sort");
  return {
    robot: params.get("robot"),
    component: params.get("robot") !== null ? params.get("component") : null,
    levels,
    q: params.get("q") || "",
    sort: SORTS.includes(sort) ? sort : "name",
  };
}

/** The query string of the fleet view with `view`'s filter ("" when there is none). */
export function fleetQuery(view) {
  const parts = [];
  if (view.levels.size) parts.push(`level=${STATES.filter((s) => view.levels.has(s)).join(",")}`);
  if (view.q) parts.push(`q=${encodeURIComponent(view.q)}`);
  if (view.sort !== "name") parts.push(`sort=${encodeURIComponent(view.sort)}`);
  return parts.length ? `?${parts.join("&")}` : "";
}

/** The query string of one robot's view, its timeline narrowed to `component` when given. */
export function robotQuery(name, component = null) {
  const narrowed = component === null ? "" : `&component=${encodeURIComponent(component)}`;
  return `?robot=${encodeURIComponent(name)}${narrowed}`;
}

/** A page link: this page's path with `query` ("" keeps the bare path). */
export function pageHref(query) {
  return query || location.pathname;
}
