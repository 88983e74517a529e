// The fleet view: counts per level, robots grouped by namespace prefix or by a label, filtered, searched
// and sorted, and the components across the fleet that match the filter (found by the exporter, bounded).

import {STATES, agoText, badge, durationText, element, rank, timeText, worstState} from "./dom.js";
import {hasLabels, labelText} from "./labels.js";
import {pageHref, robotQuery} from "./location.js";
import {MAINTENANCE, shownState} from "./maintenance.js";

const collator = new Intl.Collator(undefined, {numeric: true});
const NO_NAMESPACE = "";
// A large fleet's page lists a bounded number of rows, so that its first render and every refresh
// build a few hundred table rows, not one per robot: the counts above and in each group's header still
// cover every robot, the sort decides which come first, and each group lists more on request.
const GROUP_ROWS = 100;  // rows a group lists at first
const PAGE_ROWS = 500;  // rows the groups list at first together, in their order
const MORE_ROWS = 500;  // rows "list more" adds

/** The group a robot belongs to: the first segment of a namespaced name ("site2/robot7" → "site2"). */
export function namespaceOf(name) {
  const slash = name.indexOf("/");
  return slash > 0 ? name.slice(0, slash) : NO_NAMESPACE;
}

const COMPARE = {
  name: (a, b) => collator.compare(a.robot, b.robot),
  level: (a, b) => rank(shownState(b)) - rank(shownState(a)) || collator.compare(a.robot, b.robot),
  errors: (a, b) => b.counts.error - a.counts.error || b.counts.warn - a.counts.warn
    || collator.compare(a.robot, b.robot),
  last_message: (a, b) => (a.last_message ?? -Infinity) - (b.last_message ?? -Infinity)
    || collator.compare(a.robot, b.robot),
};

/** The robots `view` shows, sorted: level filter on the robot's level, text on its name or components,
 * label filter on its labels. A robot in maintenance has no level here: the level filters leave it out. */
export function visibleRobots(robots, view, matchedRobots) {
  const needle = view.q.toLowerCase();
  const shown = robots.filter((robot) =>
    (!view.levels.size || view.levels.has(shownState(robot)))
    && hasLabels(robot, view.labels)
    && (!needle || robot.robot.toLowerCase().includes(needle) || matchedRobots.has(robot.robot)));
  return shown.sort(COMPARE[view.sort] || COMPARE.name);
}

/** Groups of robots by namespace, or by their value of the label `grouping` ("" for those without it),
 * in the order of their first robot in `robots`; label groups `byValue` in the order of their values,
 * the robots without the label last. */
export function groupRobots(robots, grouping = null, byValue = false) {
  const groups = new Map();
  for (const robot of robots) {
    const name = grouping === null ? namespaceOf(robot.robot) : (robot.labels?.[grouping] ?? "");
    if (!groups.has(name)) groups.set(name, []);
    groups.get(name).push(robot);
  }
  if (grouping === null || !byValue) return groups;
  return new Map([...groups].sort(([a], [b]) => (a === "") - (b === "") || collator.compare(a, b)));
}

function groupTitle(name, grouping) {
  if (grouping !== null) return labelText(grouping, name);
  return name === NO_NAMESPACE ? "(no namespace)" : `${name}/`;
}

/** Why a robot is down ("down: publisher left", "never heard: listed in the inventory"); null while up. */
export function downText(robot, now) {
  if (robot.up) return null;
  switch (robot.down_reason) {
    case "never_heard": return robot.listed ? "never heard: listed in the inventory" : "never heard";
    case "silent": return `down: silent for ${durationText(now - robot.last_message)}`;
    case "publisher_left": return "down: publisher left";
    default: return "down";
  }
}

/** The fleet's "last message" of a robot: how long ago, and when it is down, why. */
function lastMessageText(robot, now) {
  const reason = downText(robot, now);
  if (reason === null) return agoText(robot.last_message, now);
  if (robot.last_message === null || robot.down_reason === "silent") return reason;
  return `${reason}, last message ${agoText(robot.last_message, now)}`;
}

/** The counts per level at the top; each level is a toggle of the level filter. Robots in maintenance
 * are counted apart, not by level, and not as down. */
export function renderSummary(robotsDocument, view, onToggleLevel) {
  const robots = robotsDocument.robots;
  const totals = Object.fromEntries(STATES.map((s) => [s, 0]));
  const components = Object.fromEntries(STATES.map((s) => [s, 0]));
  let down = 0;
  let inMaintenance = 0;
  for (const robot of robots) {
    if (robot.maintenance) inMaintenance += 1;
    else totals[robot.state] += 1;
    if (!robot.up && !robot.maintenance) down += 1;
    for (const state of STATES) components[state] += robot.counts[state.toLowerCase()];
  }
  const chips = STATES.map((state) => {
    const chip = element("button", {type: "button", class: `chip ${state}`, "data-level": state,
                                    "aria-pressed": String(view.levels.has(state)),
                                    title: `${components[state]} components ${state}`},
      `${state} `, element("b", {"data-total": state}, String(totals[state])));
    chip.addEventListener("click", () => onToggleLevel(state));
    return chip;
  });
  const componentTotal = STATES.reduce((sum, s) => sum + components[s], 0);
  document.getElementById("summary").replaceChildren(...chips,
    element("span", {class: "fact", "data-total": "robots"}, `${robots.length} robots`),
    element("span", {class: "fact", "data-total": "down"}, `down ${down}`),
    element("span", {class: "fact", "data-total": "maintenance"}, `in maintenance ${inMaintenance}`),
    element("span", {class: "fact", "data-total": "components"},
      `${componentTotal} components: ${STATES.map((s) => `${components[s]} ${s}`).join(", ")}`));
}

/** The robots, grouped, as the filter and sort of `view` ask; `openGroups` keeps the user's choices of
 * open groups, `listedRows` the rows they asked each group to list (`onListMore` renders again). */
export function renderRobots(robotsDocument, view, matchedRobots, {openGroups, listedRows}, onOpenRobot, onListMore) {
  const now = robotsDocument.generated_at;
  const shown = visibleRobots(robotsDocument.robots, view, matchedRobots);
  const labelled = robotsDocument.robots.some((robot) => Object.keys(robot.labels || {}).length > 0);
  const headings = ["Level", "Robot", ...(labelled ? ["Labels"] : []), "Components", "Last message"];
  const refocus = focusedListButton();
  const sections = [];
  let budget = PAGE_ROWS;
  let listedTotal = 0;
  for (const [name, robots] of groupRobots(shown, view.group, view.sort === "name")) {
    const key = `${view.group ?? ""}\u0000${name}`;
    const title = groupTitle(name, view.group);
    const judged = robots.filter((r) => !r.maintenance);
    const worst = judged.length ? worstState(judged.map((r) => r.state)) : MAINTENANCE;
    const perState = [...STATES, MAINTENANCE].map((s) => [s, robots.filter((r) => shownState(r) === s).length])
      .filter(([, n]) => n);
    // What the user asked a group to list comes on top of its share of the page: it takes no other
    // group's rows, and never lists fewer than that share (the group may have grown since).
    const share = Math.min(robots.length, GROUP_ROWS, budget);
    budget -= share;
    const listed = Math.min(robots.length, Math.max(share, listedRows.get(key) ?? 0));
    listedTotal += listed;
    const listMore = (count) => {
      listedRows.set(key, count);
      onListMore();
    };
    const details = element("details", {class: "group", "data-group": name, open: openGroups.get(key) ?? true},
      element("summary", {},
        badge(worst), " ",
        element("span", {class: "group-name"}, title),
        element("small", {}, `${robots.length} robots: ${perState.map(([s, n]) => `${n} ${s}`).join(", ")}`)),
      listed > 0 ? element("table", {class: "robots"},
        element("thead", {}, element("tr", {}, ...headings.map((h) => element("th", {}, h)))),
        element("tbody", {}, ...robots.slice(0, listed).map((robot) => robotRow(robot, now, labelled, onOpenRobot))))
        : null,
      listed < robots.length ? moreRows(listed, robots.length, title, view.sort, listMore) : null);
    details.firstChild.addEventListener("click", () => openGroups.set(key, !details.open));
    sections.push(details);
  }
  const unlisted = listedTotal < shown.length ? `, ${listedTotal} listed` : "";
  document.getElementById("showing").textContent =
    `Showing ${shown.length} of ${robotsDocument.robots.length} robots${unlisted}`;
  document.getElementById("groups").replaceChildren(...sections);
  if (refocus !== null) focusAgain(sections, refocus);
}

/** Below a group that lists `listed` of its `total` robots: how many are not listed, and buttons that list
 * more (`listMore` is given the rows to list). */
function moreRows(listed, total, title, sort, listMore) {
  const button = (kind, text, label, count) => {
    const node = element("button", {type: "button", "data-list": kind, "data-from": String(listed),
                                    "aria-label": label}, text);
    node.addEventListener("click", () => listMore(count));
    return node;
  };
  const order = sort === "name" ? "by name" : "the sort's first";
  const more = Math.min(MORE_ROWS, total - listed);
  return element("p", {class: "more-rows"},
    listed === 0 ? `${total} robots not listed ` : `${total - listed} more robots not listed (${listed} listed, ${order}) `,
    more < total - listed
      ? button("more", `list ${more} more`, `list ${more} more robots of ${title}`, listed + more) : null,
    " ",
    button("all", `list all ${total}`, `list all ${total} robots of ${title}`, Infinity));
}

/** The "list more" button that has the focus, if one has: {group, kind, from}; else null. */
function focusedListButton() {
  const focused = document.activeElement;
  const group = focused?.closest?.("details.group");
  if (!group || focused.dataset.list === undefined) return null;
  return {group: group.dataset.group, kind: focused.dataset.list, from: Number(focused.dataset.from)};
}

/** The focus back where it was after the groups were built again: on the same button of the same group,
 * or, that button gone (the group lists them all), on the first robot it had not listed. */
function focusAgain(sections, {group, kind, from}) {
  const section = sections.find((details) => details.dataset.group === group);
  if (!section) return;
  const target = section.querySelector(`.more-rows button[data-list="${kind}"]`)
    ?? section.querySelectorAll("tr[data-robot] a")[from];
  target?.focus();
}

function robotRow(robot, now, labelled, onOpenRobot) {
  const c = robot.counts;
  const m = robot.maintenance;
  const seen = lastMessageText(robot, now);
  return element("tr", {"data-robot": robot.robot, "data-state": shownState(robot),
                        "data-down-reason": robot.up ? null : robot.down_reason,
                        class: m ? "maintenance" : (robot.up ? null : "down")},
    element("td", {}, badge(shownState(robot))),
    element("td", {class: "robot-name"}, robotLink(robot.robot, onOpenRobot)),
    labelled ? element("td", {class: "labels"}, ...labelTags(robot.labels)) : null,
    element("td", {}, `${c.error} error · ${c.warn} warn · ${c.stale} stale · ${c.ok} ok`
      + (m ? ` (${robot.up ? robot.state : "DOWN"})` : "")),
    element("td", {}, m ? element("span", {class: "maintenance-note", title: m.comment},
      `until ${timeText(m.until)} · ${m.author}: ${m.comment} · ${seen}`) : seen));
}

/** A robot's labels as tags, sorted by name: "site=site_a". */
export function labelTags(labels) {
  return Object.keys(labels || {}).sort().map((name) =>
    element("span", {class: "label", "data-label": name}, labelText(name, labels[name])));
}

/** A link to a robot's view that navigates in place (a new tab still works: it is a real link). */
export function robotLink(name, onOpenRobot) {
  const link = element("a", {href: pageHref(robotQuery(name))}, name);
  link.addEventListener("click", (event) => {
    if (event.button !== 0 || event.ctrlKey || event.metaKey || event.shiftKey || event.altKey) return;
    event.preventDefault();
    onOpenRobot(name);
  });
  return link;
}

/** The components matching the filter across the fleet, as the exporter found them (worst first); of
 * `labelledRobots` only, when a label filter keeps some (the fleet's worst on them are their worst too). */
export function renderMatches(matches, view, labelledRobots, onOpenRobot) {
  const section = document.getElementById("matches");
  section.hidden = matches === null;
  if (matches === null) return;
  const scoped = labelledRobots !== null;
  const rows = matches.components.filter((c) => !scoped || labelledRobots.has(c.robot));
  const total = scoped
    ? matches.robots.reduce((sum, r) => sum + (labelledRobots.has(r.robot) ? r.matches : 0), 0)
    : matches.total;
  if (view.sort === "name") {
    rows.sort((a, b) => collator.compare(a.robot, b.robot) || collator.compare(a.name, b.name));
  }
  let count = `${total} components match`;
  if (rows.length === 0 && total > 0) {
    count += `; none among the fleet's ${matches.limit} worst: narrow the search`;
  } else if (rows.length < total) {
    count += `; the ${rows.length} worst are shown`;
  }
  document.getElementById("matches-count").textContent = count;
  document.getElementById("matches-rows").replaceChildren(...rows.map((c) =>
    element("tr", {"data-robot": c.robot, "data-component": c.name, "data-state": c.state},
      element("td", {}, badge(c.state)),
      element("td", {}, robotLink(c.robot, onOpenRobot)),
      element("td", {}, c.name),
      element("td", {}, c.hardware_id),
      element("td", {}, c.message))));
}
