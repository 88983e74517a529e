// The inventory's labels on the fleet view (site, model, team, …): which robots a label filter keeps,
// which group a robot falls in, and the controls that choose both ("Group by" and a select per label).

import {element} from "./dom.js";

const collator = new Intl.Collator(undefined, {numeric: true});

/** True when `robot` has every label of `wanted` (name → value; "" asks for a robot without it). */
export function hasLabels(robot, wanted) {
  for (const [name, value] of wanted) {
    if ((robot.labels?.[name] ?? "") !== value) return false;
  }
  return true;
}

/** Every label name in the fleet, and per name its values, each sorted. */
export function fleetLabels(robots) {
  const values = new Map();
  for (const robot of robots) {
    for (const [name, value] of Object.entries(robot.labels || {})) {
      if (!values.has(name)) values.set(name, new Set());
      values.get(name).add(value);
    }
  }
  return new Map([...values.keys()].sort(collator.compare)
    .map((name) => [name, [...values.get(name)].sort(collator.compare)]));
}

/** "site=site_a" for a group's or a filter's label; "(no site)" for the robots without it. */
export function labelText(name, value) {
  return value === "" ? `(no ${name})` : `${name}=${value}`;
}

/** The "Group by" choices (namespace, then each label name) and a select per label filtering on it.

The labels shown are the fleet's and those `view` names (a deep link may ask for one no robot has).
Controls are rebuilt only when their choices change, so that a select the user holds open stays open.
`onGroup(name or null)` and `onFilter(name, value or null for all)` report the user's choice. */
export function renderLabelControls(robots, view, onGroup, onFilter) {
  const labels = fleetLabels(robots);
  for (const [name, value] of view.labels) {
    const values = labels.get(name) || [];
    if (value !== "" && !values.includes(value)) values.push(value);
    labels.set(name, values.sort(collator.compare));
  }
  if (view.group !== null && !labels.has(view.group)) labels.set(view.group, []);
  const names = [...labels.keys()].sort(collator.compare);

  const group = document.getElementById("group");
  const groups = [null, ...names];
  if (group.dataset.choices !== JSON.stringify(names)) {
    group.replaceChildren(...groups.map((name) => element("option", {}, name ?? "namespace")));
    group.dataset.choices = JSON.stringify(names);
    group.onchange = () => onGroup(groups[group.selectedIndex]);
  }
  group.selectedIndex = groups.indexOf(view.group);

  const filters = document.getElementById("label-filters");
  const shape = JSON.stringify(names.map((name) => [name, labels.get(name)]));
  if (filters.dataset.choices !== shape) {
    filters.replaceChildren(...names.map((name) => labelSelect(name, labels.get(name), onFilter)));
    filters.dataset.choices = shape;
  }
  for (const select of filters.querySelectorAll("select")) {
    const name = select.dataset.label;
    select.selectedIndex = choicesOf(labels.get(name)).indexOf(view.labels.get(name) ?? null);
  }
}

/** A label filter's choices: null for all robots, each value, "" for the robots without the label. */
function choicesOf(values) {
  return [null, ...values, ""];
}

function labelSelect(name, values, onFilter) {
  const choices = choicesOf(values);
  const select = element("select", {"data-label": name},
    ...choices.map((value) => element("option", {}, value === null ? "all" : (value || `(no ${name})`))));
  select.addEventListener("change", () => onFilter(name, choices[select.selectedIndex]));
  return element("label", {class: "label-filter"}, `${name} `, select);
}
