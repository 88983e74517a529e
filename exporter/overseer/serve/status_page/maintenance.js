// Maintenance windows on the page: who is in one, until when and why, and, for users the exporter lets
// write, forms to start a window and buttons to end one. The forms are in index.html, so a refresh never
// loses what the user is typing; only the lists are rebuilt.

import {element, getJson, sendJson, timeText} from "./dom.js";

export const MAINTENANCE = "MAINTENANCE";

/** The state a robot is shown in: MAINTENANCE while it is in a window, else its level (or STALE if down). */
export function shownState(robot) {
  return robot.maintenance ? MAINTENANCE : robot.state;
}

/** "until 14:00 · alice: battery swap" for a robot's `maintenance`. */
export function maintenanceText(maintenance) {
  return `in maintenance until ${timeText(maintenance.until)} · ${maintenance.author}: ${maintenance.comment}`;
}

/** The windows and whether this user may write them; an exporter without the API gives none. */
export async function loadMaintenance() {
  try {
    return await getJson("api/v1/maintenance");
  } catch (error) {
    if (error.status === 404) return {windows: [], can_write: false};
    throw error;
  }
}

/** The fleet view's list of windows (with an end button each, for writers) and its start form. */
export function renderMaintenancePanel(listing, onChanged) {
  const now = Date.now() / 1000;
  const windows = listing.windows.filter((w) => w.end > now);
  const section = document.getElementById("maintenance");
  section.hidden = windows.length === 0 && !listing.can_write;
  document.getElementById("maintenance-form").hidden = !listing.can_write;
  document.getElementById("maintenance-none").hidden = windows.length > 0;
  document.getElementById("maintenance-table").hidden = windows.length === 0;
  document.getElementById("maintenance-rows").replaceChildren(...windows.map((w) =>
    element("tr", {"data-window": w.id, "data-active": String(w.active)},
      element("td", {class: "robot-name"}, w.robots),
      element("td", {}, w.active ? "active" : "scheduled"),
      element("td", {}, timeText(w.start)),
      element("td", {}, timeText(w.end)),
      element("td", {}, w.author),
      element("td", {class: "message"}, w.comment),
      element("td", {}, listing.can_write && !w.recurring
        ? endButton(w, "maintenance-error", onChanged)
        : (w.recurring ? "recurring (configuration)" : "")))));
}

/** The robot view's line on its window, with an end button, or a start form for writers. */
export function renderRobotMaintenance(robot, listing, onChanged) {
  const box = document.getElementById("robot-maintenance");
  const state = document.getElementById("robot-maintenance-state");
  const current = robot && robot.maintenance;
  box.hidden = robot === null || (!current && !listing.can_write);
  box.dataset.robot = robot ? robot.robot : "";
  document.getElementById("robot-maintenance-form").hidden = !listing.can_write || Boolean(current);
  const end = document.getElementById("robot-maintenance-end");
  if (!current) {
    state.replaceChildren();
    end.replaceChildren();
    return;
  }
  const held = listing.windows.find((w) => w.id === current.window);
  state.replaceChildren(element("span", {class: "badge MAINTENANCE"}, MAINTENANCE), " ",
    maintenanceText(current), held ? ` (window ${held.id} for ${held.robots})` : "");
  end.replaceChildren(...(listing.can_write && held && !held.recurring
    ? [endButton(held, "robot-maintenance-error", onChanged)] : []));
}

function endButton(held, errorId, onChanged) {
  const label = held.robots.endsWith("/") ? `End maintenance of ${held.robots}` : "End maintenance";
  const button = element("button", {type: "button", class: "end-maintenance", "data-window": held.id}, label);
  button.addEventListener("click", async () => {
    button.disabled = true;
    await write(errorId, () => sendJson("DELETE", `api/v1/maintenance/${encodeURIComponent(held.id)}`));
    onChanged();
  });
  return button;
}

async function write(errorId, send) {
  const error = document.getElementById(errorId);
  try {
    await send();
    error.textContent = "";
    return true;
  } catch (failure) {
    error.textContent = failure.message;
    return false;
  }
}

/** Wire the start forms (once): the fleet's for any robots, the robot view's for the robot shown. */
export function setUpMaintenanceForms(currentRobot, onChanged) {
  const fleetForm = document.getElementById("maintenance-form");
  fleetForm.addEventListener("submit", async (event) => {
    event.preventDefault();
    const body = {
      robots: document.getElementById("maintenance-robots").value.trim(),
      duration: document.getElementById("maintenance-duration").value,
      comment: document.getElementById("maintenance-comment").value,
    };
    if (await write("maintenance-error", () => sendJson("POST", "api/v1/maintenance", body))) fleetForm.reset();
    onChanged();
  });
  const robotForm = document.getElementById("robot-maintenance-form");
  robotForm.addEventListener("submit", async (event) => {
    event.preventDefault();
    const body = {
      robots: currentRobot(),
      duration: document.getElementById("robot-maintenance-duration").value,
      comment: document.getElementById("robot-maintenance-comment").value,
    };
    if (await write("robot-maintenance-error", () => sendJson("POST", "api/v1/maintenance", body))) robotForm.reset();
    onChanged();
  });
}
