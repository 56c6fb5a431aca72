// The live view's page (docs/view.md): frames from /ws, one plot per state component
// (truth, each estimator's x̂ and its ±2σ band), a strip per sensor node and the latency.
// `window.viewState` holds what a test reads.
'use strict';

const MAX_POINTS = 20000; // per series, oldest dropped
const STRIP_COLORS = ['#3a9d3a', '#f0a030', '#d62728', '#8e44ad'];
// The after-run plots' palette (plot::color in ipc-runner/src/plot/mod.rs): Okabe–Ito, then
// darker variants; black is the truth's.
const EST_COLORS = ['#0072b2', '#d55e00', '#009e73', '#cc79a7', '#e69f00', '#56b4e9',
  '#787878', '#967800', '#00466e', '#8c3c00', '#006446', '#82466e'];

const S = (window.viewState = {
  connected: false, state: 'connecting', instants: 0, frames: 0, names: [], nx: 0,
  nodes: 0, points: {}, bandsDrawn: 0, latency: null, dropped_frames: 0,
});

let d = null; // {k, truth[j][], x[e][j][], lo[e][j][], hi[e][j][], st[]}
let plots = [];
let latPlot = null;
let lat = { t: [], p50: [], p99: [] };
let dirty = false;

function reset() {
  d = null;
  for (const p of plots) p.destroy();
  plots = [];
  document.getElementById('plots').innerHTML = '';
  lat = { t: [], p50: [], p99: [] };
  S.instants = 0; S.frames = 0; S.points = {}; S.bandsDrawn = 0;
}

function hexA(c, a) {
  const n = parseInt(c.slice(1), 16);
  return `rgba(${n >> 16},${(n >> 8) & 255},${n & 255},${a})`;
}

function build(names, nx) {
  reset();
  S.names = names; S.nx = nx;
  d = { k: [], truth: [], x: [], lo: [], hi: [], st: [] };
  for (let j = 0; j < nx; j++) d.truth.push([]);
  for (let e = 0; e < names.length; e++) {
    d.x.push([]); d.lo.push([]); d.hi.push([]);
    for (let j = 0; j < nx; j++) { d.x[e].push([]); d.lo[e].push([]); d.hi[e].push([]); }
  }
  const width = Math.max(600, Math.min(1200, window.innerWidth - 40));
  for (let j = 0; j < nx; j++) {
    const series = [{ label: 'k' }, { label: 'truth', stroke: '#000', width: 1.5, dash: [4, 3] }];
    const bands = [];
    names.forEach((n, e) => {
      const c = EST_COLORS[e % EST_COLORS.length];
      const base = series.length;
      series.push({ label: n, stroke: c, width: 1.5 });
      series.push({ label: n + ' −2σ', stroke: hexA(c, 0.35), width: 1 });
      series.push({ label: n + ' +2σ', stroke: hexA(c, 0.35), width: 1 });
      bands.push({ series: [base + 2, base + 1], fill: hexA(c, 0.12) });
    });
    const div = document.createElement('div');
    div.className = 'panel';
    div.innerHTML = `<h2>x<sub>${j + 1}</sub>: truth, x̂ and ±2σ</h2>`;
    document.getElementById('plots').appendChild(div);
    const opts = {
      width, height: 220, series, bands,
      scales: { x: { time: false } },
      axes: [{ label: 'k' }, {}],
      legend: { live: false },
      hooks: { draw: [u => countBands(u)] },
    };
    plots.push(new uPlot(opts, emptyData(j), div));
  }
}

function emptyData(j) {
  const out = [d.k, d.truth[j]];
  for (let e = 0; e < S.names.length; e++) out.push(d.x[e][j], d.lo[e][j], d.hi[e][j]);
  return out;
}

// Bands drawn: per plot, the bands whose edges hold at least one number.
const drawn = new Map();
function countBands(u) {
  let n = 0;
  for (const b of u.bands || []) {
    const hi = u.data[b.series[0]];
    if (hi && hi.some(v => v != null)) n++;
  }
  drawn.set(u, n);
  let total = 0;
  for (const p of plots) total += drawn.get(p) || 0;
  S.bandsDrawn = total;
}

function trim(a) { if (a.length > MAX_POINTS) a.splice(0, a.length - MAX_POINTS); }

function onFrame(f) {
  S.frames++;
  S.state = f.state;
  S.instants = f.instants;
  S.nodes = f.nodes;
  const names = f.names || [];
  if (!d || names.length !== S.names.length || f.nx !== S.nx) {
    if (f.nx > 0 && names.length > 0) build(names, f.nx);
  }
  if (d) {
    for (const p of f.points || []) {
      d.k.push(p.k);
      for (let j = 0; j < S.nx; j++) d.truth[j].push(p.truth ? p.truth[j] : null);
      for (let e = 0; e < S.names.length; e++) {
        const est = p.est ? p.est[e] : null;
        for (let j = 0; j < S.nx; j++) {
          const x = est ? est[0][j] : null;
          const s = est ? est[1][j] : null;
          d.x[e][j].push(x);
          const band = x != null && s != null && isFinite(s);
          d.lo[e][j].push(band ? x - 2 * s : null);
          d.hi[e][j].push(band ? x + 2 * s : null);
        }
      }
      d.st.push(p.st || []);
    }
    if (d.k.length > MAX_POINTS) {
      const drop = d.k.length - MAX_POINTS;
      for (const a of [d.k, d.st, ...d.truth, ...d.x.flat(), ...d.lo.flat(), ...d.hi.flat()]) a.splice(0, drop);
    }
    S.points = { truth: d.truth.length ? d.truth[0].filter(v => v != null).length : 0 };
    S.names.forEach((n, e) => { S.points[n] = d.x[e][0].filter(v => v != null).length; });
    S.points.k = d.k.length;
  }
  if (f.latency && f.latency.window > 0) {
    lat.t.push(f.instants); lat.p50.push(f.latency.p50_us); lat.p99.push(f.latency.p99_us);
    for (const a of [lat.t, lat.p50, lat.p99]) trim(a);
    S.latency = f.latency;
  }
  S.totals = f.totals;
  dirty = true;
}

function drawStrip() {
  const c = document.getElementById('strip');
  const n = Math.max(1, S.nodes);
  c.height = 14 * n;
  const g = c.getContext('2d');
  g.clearRect(0, 0, c.width, c.height);
  if (!d) return;
  const cells = Math.floor(c.width / 2);
  const from = Math.max(0, d.st.length - cells);
  for (let i = from; i < d.st.length; i++) {
    const st = d.st[i];
    for (let m = 0; m < st.length; m++) {
      g.fillStyle = STRIP_COLORS[st[m]] || '#999';
      g.fillRect((i - from) * 2, m * 14 + 1, 2, 12);
    }
  }
  const t = document.getElementById('node-totals');
  t.textContent = (S.totals || []).map((c, m) =>
    `node ${m}: ${c[0]} delivered, ${c[1]} dropped, ${c[2]} lost, ${c[3]} late`).join(' · ');
}

function drawLatency() {
  const el = document.getElementById('latency');
  const l = S.latency;
  el.textContent = l ? `latency p50 ${l.p50_us?.toFixed(1)} µs · p99 ${l.p99_us?.toFixed(1)} µs (${l.window} instants)` : '';
  if (!latPlot && lat.t.length) {
    latPlot = new uPlot({
      width: Math.max(600, Math.min(1200, window.innerWidth - 40)), height: 160,
      scales: { x: { time: false } }, axes: [{ label: 'instants' }, { label: 'µs' }],
      series: [{}, { label: 'p50', stroke: '#1f77b4' }, { label: 'p99', stroke: '#d62728' }],
    }, [lat.t, lat.p50, lat.p99], document.getElementById('latplot'));
  } else if (latPlot) {
    latPlot.setData([lat.t, lat.p50, lat.p99]);
  }
}

function render() {
  if (dirty) {
    dirty = false;
    plots.forEach((p, j) => p.setData(emptyData(j)));
    drawStrip();
    drawLatency();
    const badge = document.getElementById('state');
    badge.textContent = S.connected ? S.state : 'disconnected';
    badge.className = (S.connected ? S.state : 'disconnected').replace(/ /g, '-');
    document.getElementById('instants').textContent = `${S.instants} instants`;
  }
  requestAnimationFrame(render);
}

function connect() {
  const ws = new WebSocket(`ws://${location.host}/ws`);
  ws.onopen = () => { S.connected = true; dirty = true; };
  ws.onmessage = ev => {
    let f;
    try { f = JSON.parse(ev.data); } catch (e) { return; }
    if (f.reset) { reset(); S.names = []; S.nx = 0; return; }
    onFrame(f);
  };
  ws.onclose = () => {
    S.connected = false; dirty = true;
    setTimeout(connect, 1000);
  };
}

requestAnimationFrame(render);
connect();
