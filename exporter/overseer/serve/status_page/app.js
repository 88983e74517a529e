// The status page: reads the view from the URL, fetches what it needs from the exporter, renders, and
// refreshes every few seconds keeping the filter, the scroll position and the open folders.

import {agoText, badge, element, getJson, timeText} from "./dom.js";
import {downText, labelTags, renderMatches, renderRobots, renderSummary} from "./fleet.js";
import {hasLabels, renderLabelControls} from "./labels.js";
import {fleetQuery, pageHref, readQuery, robotQuery} from "./location.js";
import {
  MAINTENANCE, loadMaintenance, renderMaintenancePanel, renderRobotMaintenance, setUpMaintenanceForms,
} from "./maintenance.js";
import {Timeline} from "./timeline.js";
import {buildTree, renderTree} from "./tree.js";

const REFRESH_MS = 2000;
// A refresh that took long (a large fleet's answers on a busy exporter) waits this many times as long
// before the next, up to REFRESH_MAX_MS: an idle open page keeps the exporter busy a fifth of the time at
// most. A refresh that failed is tried again after REFRESH_MS.
const REFRESH_BACKOFF = 4;
const REFRESH_MAX_MS = 30000;
const MATCH_LIMIT = 200;
const SEARCH_DELAY_MS = 250;

const openGroups = new Map();  // fleet groups the user opened or closed, by grouping and group
const listedRows = new Map();  // rows the user asked a fleet group to list, by grouping and group
const openFolders = new Map();  // robot name → its folders the user opened or closed, by path
let view = readQuery(location.search);
let timeline = null;
let timer = null;
let generation = 0;  // a render started for an older view is dropped
let rendered = false;
let counting = null;  // the robot view's read of the fleet's counts, started by the refresh under way
let shownFleet = null;  // the fleet view shown: its view, robots document and the robots its search matched

function setView(next, how) {
  view = next;
  const query = view.robot !== null ? robotQuery(view.robot, view.component) : fleetQuery(view);
  if (how === "push") history.pushState(null, "", pageHref(query));
  else if (how === "replace") history.replaceState(null, "", pageHref(query));
  refresh();
}

function openRobot(name) {
  setView({...view, robot: name, component: null}, "push");
  window.scrollTo(0, 0);
}

function toggleLevel(state) {
  const levels = new Set(view.levels);
  if (levels.has(state)) levels.delete(state); else levels.add(state);
  setView({...view, robot: null, levels}, view.robot === null ? "replace" : "push");
}

function groupBy(label) {
  setView({...view, robot: null, group: label}, "replace");
}

function filterLabel(name, value) {
  const labels = new Map(view.labels);
  if (value === null) labels.delete(name); else labels.set(name, value);
  setView({...view, robot: null, labels}, "replace");
}

function showError(message) {
  document.getElementById("error").textContent = message;
}

async function renderFleet(current) {
  const filtered = current.levels.size > 0 || current.q !== "";
  const matchQuery = new URLSearchParams({limit: String(MATCH_LIMIT)});
  if (current.levels.size) matchQuery.set("level", [...current.levels].join(","));
  if (current.q) matchQuery.set("q", current.q);
  const [robots, matches, maintenance] = await Promise.all([
    getJson("api/v1/robots"),
    filtered ? getJson(`api/v1/components?${matchQuery}`) : Promise.resolve(null),
    loadMaintenance(),
  ]);
  if (current !== view) return false;
  renderMaintenancePanel(maintenance, refresh);
  const matched = new Set(current.q && matches ? matches.robots.map((r) => r.robot) : []);
  const labelled = current.labels.size
    ? new Set(robots.robots.filter((r) => hasLabels(r, current.labels)).map((r) => r.robot)) : null;
  renderSummary(robots, current, toggleLevel);
  renderLabelControls(robots.robots, current, groupBy, filterLabel);
  shownFleet = {view: current, robots, matched};
  renderRobots(robots, current, matched, {openGroups, listedRows}, openRobot, listMore);
  renderMatches(matches, current, labelled, openRobot);
  document.getElementById("fleet-view").hidden = false;
  document.getElementById("robot-view").hidden = true;
  return true;
}

/** The fleet's groups again, as the user asked one to list more rows: from the robots shown, no read. */
function listMore() {
  if (shownFleet !== null && shownFleet.view === view) {
    renderRobots(shownFleet.robots, view, shownFleet.matched, {openGroups, listedRows}, openRobot, listMore);
  }
}

function showHistoryOf(component) {
  setView({...view, component}, "push");
}

async function renderRobot(current) {
  if (timeline === null || timeline.robot !== current.robot || timeline.component !== current.component) {
    timeline = new Timeline(current.robot, current.component);
  }
  const path = `api/v1/robots/${current.robot.split("/").map(encodeURIComponent).join("/")}`;
  // the fleet's counts at the top come when they come: the robot's own view does not wait for them (the
  // next refresh does)
  counting = getJson("api/v1/robots").then((robots) => {
    if (current === view) renderSummary(robots, {...current, levels: new Set()}, toggleLevel);
  }, () => {});
  const [robot, maintenance] = await Promise.all([
    getJson(path).catch((error) => (error.status === 404 ? null : Promise.reject(error))),
    loadMaintenance(),
    timeline.refresh().catch((error) => timeline.fail(error)),
  ]);
  if (current !== view) return false;
  document.getElementById("back").href = pageHref(fleetQuery(current));
  const title = document.getElementById("robot-title");
  const tree = document.getElementById("tree");
  if (robot === null) {
    title.replaceChildren(`${current.robot}: unknown robot`);
    document.getElementById("robot-facts").textContent = "The exporter does not know this robot (yet).";
    tree.replaceChildren();
  } else {
    title.replaceChildren(badge(robot.maintenance ? MAINTENANCE : (robot.up ? robot.state : "STALE")), " ",
      element("span", {class: "node-name"}, robot.robot), `: ${robot.up ? robot.state : "DOWN"}`);
    renderRobotFacts(robot, current);
    const folders = folderMemory(current.robot);
    renderTree(tree, buildTree(robot.components), robot.generated_at, folders, showHistoryOf);
  }
  renderRobotMaintenance(robot, maintenance, refresh);
  const narrowed = document.getElementById("timeline-component");
  narrowed.hidden = current.component === null;
  narrowed.replaceChildren(`only ${current.component ?? ""} · `, allHistoryLink(current.robot));
  timeline.render();
  document.getElementById("fleet-view").hidden = true;
  document.getElementById("robot-view").hidden = false;
  document.title = `${current.robot} — Overseer`;
  return true;
}

function renderRobotFacts(robot, current) {
  const c = robot.counts;
  const heard = robot.last_message !== null
    ? `last message ${timeText(robot.last_message)} (${agoText(robot.last_message, robot.generated_at)})` : null;
  const facts = [
    downText(robot, robot.generated_at),
    robot.transport || null,
    heard,
    `${robot.components.length} components: ${c.error} error, ${c.warn} warn, ${c.stale} stale, ${c.ok} ok`,
  ].filter((fact) => fact !== null);
  const tags = labelTags(robot.labels).map((tag) => {
    const wanted = new Map([[tag.dataset.label, robot.labels[tag.dataset.label]]]);
    const fleet = {...current, robot: null, component: null, labels: wanted};
    const link = element("a", {href: pageHref(fleetQuery(fleet)), title: "the robots with this label"}, tag);
    link.addEventListener("click", (event) => {
      if (event.button !== 0 || event.ctrlKey || event.metaKey || event.shiftKey || event.altKey) return;
      event.preventDefault();
      setView(fleet, "push");
    });
    return link;
  });
  document.getElementById("robot-facts").replaceChildren(facts.join(" · "), ...tags.flatMap((tag) => [" ", tag]));
}

function allHistoryLink(robot) {
  const link = element("a", {href: pageHref(robotQuery(robot)), id: "timeline-all"}, "every component");
  link.addEventListener("click", (event) => {
    if (event.button !== 0 || event.ctrlKey || event.metaKey || event.shiftKey || event.altKey) return;
    event.preventDefault();
    setView({...view, component: null}, "push");
  });
  return link;
}

function folderMemory(robot) {
  if (!openFolders.has(robot)) openFolders.set(robot, new Map());
  return openFolders.get(robot);
}

async function refresh() {
  clearTimeout(timer);
  const mine = ++generation;
  const current = view;
  const started = performance.now();
  let failed = false;
  counting = null;
  try {
    const done = current.robot !== null ? await renderRobot(current) : await renderFleet(current);
    if (done && mine === generation) {
      showError("");
      if (current.robot === null) document.title = "Overseer — fleet status";
      if (!rendered) {
        rendered = true;
        performance.mark("overseer-first-render");
      }
      document.body.dataset.view = current.robot !== null ? "robot" : "fleet";
      document.body.dataset.refreshes = String(Number(document.body.dataset.refreshes || 0) + 1);
    }
  } catch (error) {
    failed = true;
    if (mine === generation) showError(`cannot reach the exporter: ${error.message}`);
  }
  if (counting !== null) await counting;
  const took = performance.now() - started;
  const delay = failed ? REFRESH_MS : Math.min(REFRESH_MAX_MS, Math.max(REFRESH_MS, REFRESH_BACKOFF * took));
  if (mine === generation) timer = setTimeout(refresh, delay);
}

function setUpControls() {
  const search = document.getElementById("search");
  const sort = document.getElementById("sort");
  search.value = view.q;
  sort.value = view.sort;
  let typing = null;
  search.addEventListener("input", () => {
    clearTimeout(typing);
    typing = setTimeout(() => setView({...view, robot: null, q: search.value.trim()}, "replace"), SEARCH_DELAY_MS);
  });
  document.getElementById("controls").addEventListener("submit", (event) => {
    event.preventDefault();
    clearTimeout(typing);
    setView({...view, robot: null, q: search.value.trim()}, "replace");
  });
  sort.addEventListener("change", () => setView({...view, robot: null, sort: sort.value}, "replace"));
  for (const id of ["clear", "home", "back"]) {
    document.getElementById(id).addEventListener("click", (event) => {
      if (event.button !== 0 || event.ctrlKey || event.metaKey || event.shiftKey || event.altKey) return;
      event.preventDefault();
      const next = id === "back" ? {...readQuery(new URL(event.currentTarget.href).search), robot: null}
                                 : readQuery("");
      search.value = next.q;
      sort.value = next.sort;
      setView(next, "push");
    });
  }
  window.addEventListener("popstate", () => {
    view = readQuery(location.search);
    search.value = view.q;
    sort.value = view.sort;
    refresh();
  });
}

// Links of the first page (`/#robot`) still open that robot, under the new deep link.
if (location.hash.length > 1 && view.robot === null) {
  view = {...view, robot: decodeURIComponent(location.hash.slice(1))};
  history.replaceState(null, "", pageHref(robotQuery(view.robot)));
}
setUpControls();
setUpMaintenanceForms(() => view.robot, refresh);
refresh();
