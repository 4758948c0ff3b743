"use strict";
const D = JSON.parse(document.getElementById("linkopt-data").textContent);
const M = D.motors.length;
const S = { design: 0, index: [], busy: Promise.resolve() };
const sceneDiv = document.getElementById("linkopt-scene");
const mapDiv = document.getElementById("linkopt-map");
const clearDiv = document.getElementById("linkopt-clearance");
if (!D.clearance_scale) clearDiv.style.display = "none";
const status = document.getElementById("status");

function design() { return D.designs[S.design]; }
function shape() { return design().axes.map(a => a.length); }
function flat(index) {
  let k = 0;
  const sh = shape();
  for (let m = 0; m < M; m++) k = k * sh[m] + index[m];
  return k;
}
function unflat(k) {
  const sh = shape(), out = new Array(M);
  for (let m = M - 1; m >= 0; m--) { out[m] = k % sh[m]; k = Math.floor(k / sh[m]); }
  return out;
}
// v turned by the unit quaternion (w, x, y, z): v + 2w(q x v) + 2 q x (q x v)
function turn(q, v) {
  const [w, x, y, z] = q;
  const t = [2 * (y * v[2] - z * v[1]), 2 * (z * v[0] - x * v[2]), 2 * (x * v[1] - y * v[0])];
  return [v[0] + w * t[0] + (y * t[2] - z * t[1]),
          v[1] + w * t[1] + (z * t[0] - x * t[2]),
          v[2] + w * t[2] + (x * t[1] - y * t[0])];
}
function place(state, body, local) {
  const L = D.length_scale, s = state.slice(7 * body, 7 * body + 7);
  const r = turn(s.slice(3), local);
  return [L * s[0] + r[0], L * s[1] + r[1], L * s[2] + r[2]];
}
function pointsOf(state, dsg) {
  const out = {};
  for (const p of dsg.points) out[p.name] = place(state, p.body, p.local);
  return out;
}
function motorText(index) {
  const dsg = design();
  return D.motors.map((m, i) => {
    const v = dsg.axes[i][index[i]], shown = Math.abs(v) < 1e-12 ? 0 : v;
    return `${m.name} = ${shown.toPrecision(6)} ${m.linear ? D.units : "rad"}`;
  }).join(", ");
}
function bodyTraces(state, dsg) {
  return dsg.bodies.map((b, k) => {
    const x = [], y = [], z = [];
    if (state) {
      for (const c of b.capsules) {
        const a = place(state, k, c.slice(0, 3)), e = place(state, k, c.slice(3));
        x.push(a[0], e[0], null); y.push(a[1], e[1], null); z.push(a[2], e[2], null);
      }
    }
    return { x, y, z };
  });
}
function jointTrace(state, dsg) {
  const x = [], y = [], z = [];
  if (state) dsg.bodies.forEach((b, k) => b.joints.forEach(j => {
    const p = place(state, k, j); x.push(p[0]); y.push(p[1]); z.push(p[2]);
  }));
  return { x, y, z };
}
function pointTrace(state, dsg) {
  const x = [], y = [], z = [], text = [];
  if (state) {
    const pts = pointsOf(state, dsg);
    for (const p of dsg.points) {
      const v = pts[p.name]; x.push(v[0]); y.push(v[1]); z.push(v[2]); text.push(p.name);
    }
  }
  return { x, y, z, text };
}
function fsingColour(v) { return v === null ? null : Math.log10(Math.max(v, 1e-300)); }
function cloudTraces(dsg) {
  return dsg.points.map(p => {
    const x = [], y = [], z = [], c = [];
    dsg.states.forEach((s, k) => {
      if (!s) return;
      const v = place(s, p.body, p.local);
      x.push(v[0]); y.push(v[1]); z.push(v[2]); c.push(fsingColour(dsg.f_sing[k]));
    });
    return {
      type: "scatter3d", mode: "markers", name: `${p.name} trace (colour: log10 f_sing)`,
      x, y, z, hoverinfo: "skip",
      marker: { size: 2, color: c, colorscale: "Viridis", cmin: D.f_sing_scale.low,
                cmax: D.f_sing_scale.high, opacity: 0.5 },
    };
  });
}
function targetTrace(dsg, cloud) {
  if (!D.target) return [];
  const k = dsg.points.findIndex(p => p.name === D.target.point);
  const axis = [cloud[k].x, cloud[k].y, cloud[k].z];
  const box = D.target.box.map((b, i) => b || (axis[i].length ?
    [Math.min(...axis[i]), Math.max(...axis[i])] : [0, 0]));
  const x = [], y = [], z = [];
  const corner = (a, b, c) => [box[0][a], box[1][b], box[2][c]];
  const edges = [[0,0,0,1,0,0],[0,1,0,1,1,0],[0,0,1,1,0,1],[0,1,1,1,1,1],
                 [0,0,0,0,1,0],[1,0,0,1,1,0],[0,0,1,0,1,1],[1,0,1,1,1,1],
                 [0,0,0,0,0,1],[1,0,0,1,0,1],[0,1,0,0,1,1],[1,1,0,1,1,1]];
  for (const e of edges) {
    const a = corner(e[0], e[1], e[2]), b = corner(e[3], e[4], e[5]);
    x.push(a[0], b[0], null); y.push(a[1], b[1], null); z.push(a[2], b[2], null);
  }
  return [{ type: "scatter3d", mode: "lines", name: "target range", x, y, z,
            line: { color: "#ff00ff", width: 3 }, hoverinfo: "skip" }];
}
// a synthesis target's points (numbered in order) and the curve the cycle traces
function curveTraces(dsg) {
  const c = dsg.curve;
  if (!c) return [];
  const col = i => c.traced.map(p => (p === null ? null : p[i]));
  return [
    { type: "scatter3d", mode: "lines", name: `${c.name}: traced over the cycle`,
      x: col(0), y: col(1), z: col(2), line: { color: "#111", width: 4 }, hoverinfo: "skip" },
    { type: "scatter3d", mode: "markers+text", name: `${c.name}: targets (in order)`,
      x: c.targets.map(p => p[0]), y: c.targets.map(p => p[1]), z: c.targets.map(p => p[2]),
      text: c.targets.map((_, i) => String(i + 1)), textposition: "top center",
      marker: { size: 6, color: "#e6550d", symbol: "x" } },
  ];
}
function sceneTraces() {
  const dsg = design(), k = flat(S.index), state = dsg.states[k];
  const traces = bodyTraces(state, dsg).map((t, b) => ({
    type: "scatter3d", mode: "lines", name: dsg.bodies[b].name, x: t.x, y: t.y, z: t.z,
    line: { color: dsg.bodies[b].colour, width: 10 },
  }));
  const j = jointTrace(state, dsg);
  traces.push({ type: "scatter3d", mode: "markers", name: "joints", ...j,
                marker: { size: 4, color: "#222" } });
  const p = pointTrace(state, dsg);
  traces.push({ type: "scatter3d", mode: "markers+text", name: "points", ...p,
                marker: { size: 5, color: "#ff00ff", symbol: "diamond" } });
  const cloud = cloudTraces(dsg);
  return traces.concat(cloud, targetTrace(dsg, cloud), curveTraces(dsg));
}
// the map of one field: f_sing (viridis, log10) or the clearance (RdBu, white at the band)
function field(name) {
  const dsg = design();
  if (name === "f_sing") return { values: dsg.f_sing.map(fsingColour), low: D.f_sing_scale.low,
    high: D.f_sing_scale.high, scale: "Viridis", title: "log10 f_sing",
    text: "motor space: f_sing (brighter = closer to a singularity; black = failed)" };
  const c = D.clearance_scale;
  // plotly's RdBu runs blue to red: reversed, red is low as in matplotlib's
  return { values: dsg.clearance, low: c.low, high: c.high, scale: "RdBu", reverse: true, title: `clearance (${D.units})`,
    text: `motor space: least clearance (red: closer than ${c.band.toPrecision(3)} ${D.units}; black = failed)` };
}
function mapTraces(name) {
  const dsg = design(), f = field(name);
  // the marker takes no hover, so a click picks the map's cell under it
  const here = { type: "scatter", mode: "markers", name: "this configuration", hoverinfo: "skip",
                 marker: { size: 12, color: "rgba(0,0,0,0)", line: { color: "#ff00ff", width: 2 } } };
  if (M === 1) {
    const failed = dsg.axes[0].filter((_, i) => dsg.states[i] === null);
    const v = f.values[S.index[0]];
    here.x = [dsg.axes[0][S.index[0]]]; here.y = [v === null ? f.low : v];
    return [
      { type: "scatter", mode: "lines+markers", name: f.title, x: dsg.axes[0], y: f.values,
        marker: { size: 5, color: f.values, colorscale: f.scale, cmin: f.low, cmax: f.high,
                  reversescale: !!f.reverse } },
      { type: "scatter", mode: "markers", name: "failed", x: failed,
        y: failed.map(() => f.low), marker: { symbol: "x", color: "black", size: 8 } },
      here,
    ];
  }
  const sh = shape(), z = [];
  for (let b = 0; b < sh[1]; b++) {
    const row = [];
    for (let a = 0; a < sh[0]; a++) {
      const index = S.index.slice(); index[0] = a; index[1] = b;
      row.push(f.values[flat(index)]);
    }
    z.push(row);
  }
  here.x = [dsg.axes[0][S.index[0]]]; here.y = [dsg.axes[1][S.index[1]]];
  here.marker.line.color = "white";
  return [{ type: "heatmap", x: dsg.axes[0], y: dsg.axes[1], z, colorscale: f.scale,
            zmin: f.low, zmax: f.high, hoverongaps: true, reversescale: !!f.reverse,
            colorbar: { title: { text: f.title } } }, here];
}
// the other motors' values of a map drawn over the first two
function sliceText() {
  if (M <= 2) return "";
  return "<br>at " + motorText(S.index).split(", ").slice(2).join(", ");
}
function mapLayout(name) {
  const unit = m => D.motors[m].linear ? D.units : "rad", f = field(name);
  const layout = { margin: { l: 60, r: 10, t: 30, b: 45 }, plot_bgcolor: "black",
                   title: { text: f.text + sliceText(), font: { size: 12 } },
                   xaxis: { title: { text: `${D.motors[0].name} (${unit(0)})` } }, showlegend: false };
  if (M === 1) { layout.yaxis = { title: { text: f.title } }; layout.plot_bgcolor = "#eee"; }
  else layout.yaxis = { title: { text: `${D.motors[1].name} (${unit(1)})` } };
  return layout;
}
function statusText() {
  const dsg = design(), k = flat(S.index), ok = dsg.states[k] !== null;
  let text = `${dsg.label}: ${motorText(S.index)}. `;
  if (!ok) return text + "FAILED: the continuation from rest did not reach this configuration on the rest assembly branch; nothing is drawn (failed cells are never interpolated).";
  text += `f_sing = ${dsg.f_sing[k].toPrecision(4)}`;
  if (dsg.curve) text += dsg.curve.defect ? `. Cycle: ${dsg.curve.defect}` : ". The cycle has no defect";
  if (dsg.clearance) text += `, least clearance = ${dsg.clearance[k] === null ? "-" : dsg.clearance[k].toPrecision(4)} ${D.units}`;
  return text;
}
// one cube around every drawn place of every design's reached cells (and the target),
// seen along the axis the mechanism spans least (down onto a planar one's plane)
function sceneBox() {
  const low = [Infinity, Infinity, Infinity], high = [-Infinity, -Infinity, -Infinity];
  const add = p => p.forEach((v, i) => { low[i] = Math.min(low[i], v); high[i] = Math.max(high[i], v); });
  for (const dsg of D.designs) dsg.states.forEach(s => {
    if (s) dsg.bodies.forEach((b, k) => b.capsules.forEach(c => {
      add(place(s, k, c.slice(0, 3))); add(place(s, k, c.slice(3)));
    }));
  });
  for (const dsg of D.designs) if (dsg.curve) dsg.curve.targets.forEach(add);
  if (D.target) D.target.box.forEach((b, i) => { if (b) { low[i] = Math.min(low[i], b[0]); high[i] = Math.max(high[i], b[1]); } });
  if (!isFinite(low[0])) return { scene: { aspectmode: "data", uirevision: "keep" } };
  const span = Math.max(...high.map((h, i) => h - low[i])) * 1.15 || D.length_scale;
  const axis = i => ({ range: [(low[i] + high[i] - span) / 2, (low[i] + high[i] + span) / 2] });
  const thin = [0, 1, 2].reduce((a, i) => (high[i] - low[i] < high[a] - low[a] ? i : a), 2);
  const eye = [0.35, -0.35, 0.35], up = [0, 0, 0];
  eye[thin] = 1.8; up[thin === 2 ? 1 : 2] = 1;
  return { scene: { aspectmode: "cube", uirevision: "keep", xaxis: axis(0), yaxis: axis(1), zaxis: axis(2),
    camera: { eye: { x: eye[0], y: eye[1], z: eye[2] }, up: { x: up[0], y: up[1], z: up[2] } } } };
}
const sceneLayout = { margin: { l: 0, r: 0, t: 0, b: 0 }, uirevision: "keep",
  legend: { x: 0, y: 1 }, ...sceneBox() };
function draw() {
  const dsg = design(), k = flat(S.index);
  status.textContent = statusText();
  status.className = dsg.states[k] === null ? "failed" : "ok";
  document.querySelectorAll("input.motor").forEach((el, m) => {
    el.value = S.index[m];
    document.getElementById(`motor-value-${m}`).textContent = motorText(S.index).split(", ")[m];
  });
  S.busy = Promise.all([
    Plotly.react(sceneDiv, sceneTraces(), sceneLayout),
    Plotly.react(mapDiv, mapTraces("f_sing"), mapLayout("f_sing")),
    ...(D.clearance_scale ? [Plotly.react(clearDiv, mapTraces("clearance"), mapLayout("clearance"))] : []),
  ]);
  return S.busy;
}
function setCell(index) { S.index = index.map(Number); return draw(); }
function setDesign(k) { S.design = Number(k); return draw(); }
function controls() {
  const box = document.getElementById("controls");
  D.motors.forEach((m, i) => {
    const row = document.createElement("div");
    row.innerHTML = `<label>${m.name} <input class="motor" id="motor-${i}" type="range" min="0" max="${design().axes[i].length - 1}" step="1"></label> <span id="motor-value-${i}"></span>`;
    box.appendChild(row);
    row.querySelector("input").addEventListener("input", e => {
      const index = S.index.slice(); index[i] = Number(e.target.value); setCell(index);
    });
  });
  if (D.designs.length > 1) {
    const sel = document.createElement("select"); sel.id = "design";
    D.designs.forEach((d, k) => { const o = document.createElement("option"); o.value = k; o.textContent = d.label; sel.appendChild(o); });
    sel.addEventListener("change", e => setDesign(e.target.value));
    box.prepend(sel);
  }
}
window.linkoptView = {
  data: D,
  setCell, setDesign,
  idle: () => S.busy,
  failedCells: () => design().states.flatMap((s, k) => s === null ? [k] : []),
  cellIndex: k => unflat(k),
  state() {
    const dsg = design(), k = flat(S.index), state = dsg.states[k];
    const drawn = sceneDiv.data.find(t => t.name === "points");
    const points = {};
    drawn.text.forEach((n, i) => { points[n] = [drawn.x[i], drawn.y[i], drawn.z[i]]; });
    return { design: S.design, label: dsg.label, index: S.index.slice(), cell: k,
             motors: S.index.map((i, m) => dsg.axes[m][i]), feasible: state !== null,
             f_sing: dsg.f_sing[k], clearance: dsg.clearance ? dsg.clearance[k] : null,
             points, drawnSegments: sceneDiv.data.filter(t => t.line && t.line.width === 10)
               .reduce((n, t) => n + t.x.filter(v => v !== null).length / 2, 0),
             status: status.textContent };
  },
};
controls();
S.index = unflat(design().rest_cell);
function onClick(ev) {
    if (M < 2) { const i = design().axes[0].indexOf(ev.points[0].x); if (i >= 0) setCell([i]); return; }
    const index = S.index.slice();
    index[0] = design().axes[0].indexOf(ev.points[0].x);
    index[1] = design().axes[1].indexOf(ev.points[0].y);
    if (index[0] >= 0 && index[1] >= 0) setCell(index);
}
draw().then(() => {
  mapDiv.on("plotly_click", onClick);
  if (D.clearance_scale) clearDiv.on("plotly_click", onClick);
  document.body.dataset.ready = "1";
});
