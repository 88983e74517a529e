// A robot's timeline from the exporter's event history (GET api/v1/events), newest first. An exporter
// without that endpoint answers 404: the page then says there is no history and carries on.

import {badge, element, getJson, timeText} from "./dom.js";

const PAGE_SIZE = 50;
const KEPT = 1000;  // events kept in the page; older ones are dropped (the exporter still has them)

/** The events of one robot (of its components whose name contains `component`, when given). */
export class Timeline {
  constructor(robot, component) {
    this.robot = robot;
    this.component = component;
    this.events = new Map();  // id → event, every page loaded so far
    this.next = null;  // cursor of the page after the oldest loaded one
    this.available = true;
    this.error = null;  // why the last fetch failed, shown until one succeeds
    this.older = document.getElementById("timeline-older");
    this.older.onclick = () => this.loadOlder().then(() => this.render(), (error) => this.fail(error));
  }

  /** Fetch the newest page and merge it with what is loaded. */
  async refresh() {
    const page = await this.fetch(null);
    if (page !== null && this.next === null && this.events.size === 0) this.next = page.next;
  }

  /** Fetch the page before the oldest loaded event. */
  async loadOlder() {
    if (this.next === null) return;
    const page = await this.fetch(this.next);
    if (page !== null) this.next = page.next;
  }

  async fetch(before) {
    const query = new URLSearchParams({robot: this.robot, limit: String(PAGE_SIZE)});
    if (this.component !== null) query.set("component", this.component);
    if (before !== null) query.set("before", before);
    try {
      const page = await getJson(`api/v1/events?${query}`);
      this.available = true;
      this.error = null;
      for (const event of page.events) this.events.set(event.id, event);
      if (this.events.size > KEPT) this.dropOldest();
      return page;
    } catch (error) {
      if (error.status === 404) {
        this.available = false;
        return null;
      }
      throw error;
    }
  }

  dropOldest() {
    const newest = [...this.events.values()].sort((a, b) => b.time - a.time || b.id - a.id).slice(0, KEPT);
    this.events = new Map(newest.map((event) => [event.id, event]));
    this.next = null;  // what was dropped is no longer "older than the oldest shown"
  }

  /** Show the loaded events, newest first. */
  render() {
    const note = document.getElementById("timeline-note");
    const list = document.getElementById("timeline-events");
    if (!this.available) {
      note.textContent = "no history: this exporter keeps no event history";
      list.replaceChildren();
      this.older.hidden = true;
      return;
    }
    const events = [...this.events.values()].sort((a, b) => b.time - a.time || b.id - a.id);
    if (this.error !== null) note.textContent = `history unavailable: ${this.error.message}`;
    else note.textContent = events.length ? "" : "no events recorded for this robot yet";
    list.replaceChildren(...events.map(eventItem));
    this.older.hidden = this.next === null;
  }

  /** Remember why a fetch failed, and show it. */
  fail(error) {
    this.error = error;
    document.getElementById("timeline-note").textContent = `history unavailable: ${error.message}`;
  }
}

function eventItem(event) {
  const state = event.kind.startsWith("maintenance_") ? "MAINTENANCE"
    : event.new_state || (event.kind === "robot_up" ? "OK" : "STALE");
  return element("li", {class: "event", "data-event-id": String(event.id), "data-kind": event.kind,
                        "data-component": event.component ?? "", "data-state": state},
    element("time", {datetime: new Date(event.time * 1000).toISOString()}, timeText(event.time)),
    badge(state),
    element("span", {class: "node-name"}, event.component ?? "robot"),
    element("span", {class: "change"}, describe(event)),
    event.message ? element("span", {class: "message"}, event.message) : null);
}

function valueOf(event, key) {
  const pair = (event.values || []).find((item) => item.key === key);
  return pair ? pair.value : "?";
}

function describe(event) {
  switch (event.kind) {
    case "level": return `${event.old_state ?? "?"} → ${event.new_state ?? "?"}`;
    case "robot_down": return "robot down";
    case "robot_up": return "robot up";
    case "appeared": return `appeared${event.new_state ? ` as ${event.new_state}` : ""}`;
    case "missing": return "missing";
    case "expired": return "expired";
    case "retired": return "retired";
    case "unlisted": return "removed from the inventory";
    case "reattributed": return "reattributed to another robot";
    case "maintenance_start": return `maintenance starts (${valueOf(event, "author")}, until ${valueOf(event, "until")})`;
    case "maintenance_end": return "maintenance ends";
    default: return String(event.kind);
  }
}
