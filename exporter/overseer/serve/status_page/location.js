// The page's state lives in its URL, so that every view has a deep link an alert can point at:
//   fleet view  ?level=ERROR,WARN&q=TEXT&sort=KEY
//               &label=NAME=VALUE   only robots with that label (repeatable; NAME= : robots without it)
//               &group=NAME         robots grouped by that label instead of their namespace
//   robot view  ?robot=<percent-encoded robot name>   (names may contain "/")
//               &component=<name>   its timeline narrowed to components whose name contains this

import {STATES} from "./dom.js";

export const SORTS = ["name", "level", "errors", "last_message"];
const LABEL_NAME = /^[a-zA-Z_][a-zA-Z0-9_]*$/;  // the inventory's label names; anything else is ignored

/** The view a URL's query asks for: {robot, component, levels (a Set of state names), q, sort,
 * labels (a Map of label name → wanted value, "" for "without the label"), group (a label name or null)}. */
export function readQuery(search) {
  const params = new URLSearchParams(search);
  const levels = new Set();
  for (const value of params.getAll("level")) {
    for (const word of value.split(",")) {
      const state = word.trim().toUpperCase();
      if (STATES.includes(state)) levels.add(state);
    }
  }
  const labels = new Map();
  for (const value of params.getAll("label")) {
    const equals = value.indexOf("=");
    const name = value.slice(0, equals);
    if (equals > 0 && LABEL_NAME.test(name)) labels.set(name, value.slice(equals + 1));
  }
  const sort = params.get("sort");
  const group = params.get("group");
  return {
    robot: params.get("robot"),
    component: params.get("robot") !== null ? params.get("component") : null,
    levels,
    q: params.get("q") || "",
    sort: SORTS.includes(sort) ? sort : "name",
    labels,
    group: group !== null && LABEL_NAME.test(group) ? group : null,
  };
}

/** The query string of the fleet view with `view`'s filter ("" when there is none). */
export function fleetQuery(view) {
  const parts = [];
  if (view.levels.size) parts.push(`level=${STATES.filter((s) => view.levels.has(s)).join(",")}`);
  if (view.q) parts.push(`q=${encodeURIComponent(view.q)}`);
  if (view.sort !== "name") parts.push(`sort=${encodeURIComponent(view.sort)}`);
  for (const name of [...view.labels.keys()].sort()) {
    parts.push(`label=${name}=${encodeURIComponent(view.labels.get(name))}`);
  }
  if (view.group !== null) parts.push(`group=${view.group}`);
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
