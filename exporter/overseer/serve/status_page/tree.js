// A robot's components as a tree: path segments are folders ("/Power/Robot Battery" is the leaf
// "Robot Battery" in folder "Power"), and each folder shows the worst level beneath it by severity.
// A component the inventory expects is tagged so, and one it expects but the robot never reported
// ("/Wheels/*" for a count of them) is tagged "not reported", with no time of last update.

import {agoText, badge, element, worstState} from "./dom.js";

/** The tree of `components` (as /api/v1/robots/<robot> lists them): nodes with own components and children. */
export function buildTree(components) {
  const root = {name: "", path: "", own: [], children: new Map(), state: "OK"};
  for (const component of components) {
    const segments = component.name.split("/").filter((s) => s !== "");
    let node = root;
    let path = "";
    for (const segment of segments) {
      path += `/${segment}`;
      if (!node.children.has(segment)) {
        node.children.set(segment, {name: segment, path, own: [], children: new Map(), state: "OK"});
      }
      node = node.children.get(segment);
    }
    if (node === root) {  // a name with no segment ("" or "/") is a leaf of its own at the top
      const key = `\u0000${component.name}`;
      if (!root.children.has(key)) {
        root.children.set(key, {name: component.name || "(no name)", path: key, own: [], children: new Map(), state: "OK"});
      }
      node = root.children.get(key);
    }
    node.own.push(component);
  }
  rollUp(root);
  return root;
}

function rollUp(node) {
  const states = node.own.map((c) => c.state);
  for (const child of node.children.values()) states.push(rollUp(child));
  node.state = worstState(states);
  return node.state;
}

/** Render `tree` into `container`; folders open as `openFolders` says, else when something is not OK.

`onHistory(name)` narrows the timeline to the components whose name contains `name`. */
export function renderTree(container, tree, now, openFolders, onHistory) {
  const render = (node) => renderNode(node, now, openFolders, onHistory);
  container.replaceChildren(...[...tree.children.values()].map(render));
}

function historyButton(name, onHistory) {
  const button = element("button", {type: "button", class: "history", "data-history": name,
                                    title: "show only this in the history"}, "history");
  button.addEventListener("click", (event) => {
    event.preventDefault();  // inside a folder's summary: do not open or close it
    event.stopPropagation();
    onHistory(name);
  });
  return button;
}

function renderNode(node, now, openFolders, onHistory) {
  const historyName = node.own.length ? node.own[0].name : node.path;
  if (!node.children.size) {
    return element("div", {class: "leaf", "data-path": node.path, "data-state": node.state},
      ...node.own.flatMap((c, i) => [...(i ? [element("br")] : []), ...componentParts(c, node.name, now)]),
      historyButton(historyName, onHistory));
  }
  const details = element("details", {class: "folder", "data-path": node.path, "data-state": node.state,
                                       open: openFolders.get(node.path) ?? node.state !== "OK"},
    element("summary", {}, badge(node.state), " ", element("span", {class: "node-name"}, node.name),
      ...node.own.flatMap((c) => [" ", element("span", {class: "message", ...componentData(c)}, c.message),
        ...expectationTags(c)]),
      " ", historyButton(historyName, onHistory)),
    ...[...node.children.values()].map((child) => renderNode(child, now, openFolders, onHistory)));
  details.firstChild.addEventListener("click", () => openFolders.set(node.path, !details.open));
  return details;
}

function componentData(c) {
  return {"data-component": c.name, "data-state": c.state, "data-expected": c.expected ? "true" : null,
          "data-reported": c.reported === false ? "false" : null};
}

function expectationTags(c) {
  return [
    c.expected ? element("span", {class: "tag expected", title: "the inventory expects it"}, "expected") : null,
    c.reported === false ? element("span", {class: "tag not-reported"}, "not reported") : null,
  ].filter((tag) => tag !== null);
}

function componentParts(c, label, now) {
  const reported = c.reported !== false;  // an older exporter says nothing of it: every component was reported
  return [
    element("span", componentData(c), badge(c.state), " ",
      element("span", {class: "node-name"}, label)),
    ...expectationTags(c),
    c.hardware_id ? element("span", {class: "hardware-id"}, `[${c.hardware_id}]`) : null,
    element("span", {class: "message"}, c.message),
    c.values.length ? element("span", {class: "values"}, c.values.map((kv) => `${kv.key}=${kv.value}`).join(", ")) : null,
    reported ? element("span", {class: "updated", title: new Date(c.last_update * 1000).toISOString()},
      agoText(c.last_update, now)) : null,
  ].filter((part) => part !== null);
}
