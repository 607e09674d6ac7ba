// pendulab GUI: the page only gathers the form and draws what the server (pendulab's Python API) answers.
"use strict";

const $ = (id) => document.getElementById(id);
const MAX_UPLOAD = 1000000;  // as the server's limit: refuse a wrong file before sending it
const COLORS = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf"];
const METRICS = [
  ["verdict", "verdict", ""],
  ["stable", "stable (balanced)", ""],
  ["natural_frequency_rad_s", "natural frequency", "rad/s"],
  ["peak_time_s", "peak time", "s"],
  ["overshoot_percent", "overshoot", "%"],
  ["settling_time_s", "settling time", "s"],
  ["final_value_rad", "final value", "rad"],
  ["cart_speed_change_m_s", "cart speed change", "m/s"],
  ["safety_cut_time_s", "safety cut at", "s"],
  ["safety_cut_reason", "safety cut reason", ""],
  ["limit_cycle_amplitude_rad", "limit cycle amplitude", "rad"],
  ["limit_cycle_frequency_rad_s", "limit cycle frequency", "rad/s"],
];
// The seesaw's rows (pendulab.analysis.verdict.SEESAW_METRICS and the SPEC's, of its tilt); angles in degrees.
const DEG = 180 / Math.PI;
const SEESAW_METRICS = [
  ["verdict", "verdict", ""],
  ["peak_tilt_rad", "tap's peak tilt", "°", DEG],
  ["peak_time_s", "peak time", "s"],
  ["tilt_settling_time_s", "settled within 2° after", "s"],
  ["residual_tilt_rad", "largest tilt, last second", "°", DEG],
  ["limit_cycle_amplitude_rad", "limit cycle amplitude", "°", DEG],
  ["limit_cycle_frequency_rad_s", "limit cycle frequency", "rad/s"],
  ["natural_frequency_rad_s", "natural frequency", "rad/s"],
  ["overshoot_percent", "overshoot", "%"],
  ["max_abs_x_m", "largest |x|", "m"],
  ["safety_cut_time_s", "safety cut at", "s"],
  ["safety_cut_reason", "safety cut reason", ""],
];
// The disturbance's defaults per plant: the pendulum's poke, the seesaw's tap (about 5° of tilt).
const DISTURBANCE = { pendulum: ["poke", "50", "0.005"], seesaw: ["tap", "3.3", "0.1"] };

// Each tab has its own id: the server lists a run only in the tab that started or opened it.
let TAB = sessionStorage.getItem("pendulabTab");
if (!TAB) {
  TAB = Array.from(crypto.getRandomValues(new Uint8Array(12)), (b) => b.toString(16).padStart(2, "0")).join("");
  sessionStorage.setItem("pendulabTab", TAB);
}

// Plotly is large: load it after the form is drawn.
let plotlyReady = null;
function loadPlotly() {
  if (!plotlyReady) {
    plotlyReady = new Promise((resolve, reject) => {
      const s = document.createElement("script");
      s.src = "/static/plotly.min.js";
      s.onload = () => resolve(window.Plotly);
      s.onerror = () => reject(new Error("plotly.min.js did not load"));
      document.head.appendChild(s);
    });
  }
  return plotlyReady;
}

async function api(path, body) {
  const options = { headers: { "X-Pendulab-Tab": TAB } };
  if (body !== undefined) {
    options.method = "POST";
    options.headers["Content-Type"] = "application/json";
    options.body = JSON.stringify(body);
  }
  let response;
  try {
    response = await fetch(path, options);
  } catch (err) {
    return { ok: false, error: "the pendulab GUI server does not answer: is 'pendulab gui' still running?" };
  }
  try {
    return await response.json();
  } catch (err) {
    return { ok: false, error: `the server answered ${response.status} without a message` };
  }
}

function setStatus(el, ok, text) {
  el.className = "status " + (ok === "warn" ? "warn" : ok ? "ok" : "error");
  el.textContent = text;
}

// The run's verdict (pendulab.analysis.verdict, from metrics.json): green only for balanced without
// warnings, amber for balanced with warnings, red for a cut or a fall.
function verdictStatus(metrics) {
  const v = metrics.verdict;
  if (!v) return { ok: metrics.stable ? true : false, text: metrics.stable ? "balanced" : "not balanced" };
  const lines = [v.headline, ...v.warnings.map((w) => `  warning: ${w.kind}: ${w.text}; ${w.advice}`)];
  return { ok: v.clean ? true : v.outcome === "balanced" ? "warn" : false, text: lines.join("\n") };
}

// ------------------------------------------------------------------------------------ the form
function compRows() { return Array.from(document.querySelectorAll("tr.comp")); }

function addCompensator(values) {
  if (compRows().length >= 5) {
    setStatus($("controller-status"), false, "at most 5 compensators besides the kernel (G2..G6)");
    return;
  }
  const i = compRows().length + 2;
  const tr = document.createElement("tr");
  tr.className = "comp";
  tr.innerHTML = `<th>G${i}</th><td><input class="c-zeros"></td><td><input class="c-poles"></td>` +
    `<td><input class="c-gain"></td><td><button type="button" class="remove" title="remove">×</button></td>`;
  $("factor-rows").appendChild(tr);
  if (values) {
    tr.querySelector(".c-zeros").value = values[0];
    tr.querySelector(".c-poles").value = values[1];
    tr.querySelector(".c-gain").value = values[2] || "";
  }
  tr.querySelector(".remove").onclick = () => { tr.remove(); renumber(); controllerChanged(); };
  tr.querySelectorAll("input").forEach((inp) => inp.addEventListener("input", controllerChanged));
}

function renumber() { compRows().forEach((tr, k) => { tr.querySelector("th").textContent = `G${k + 2}`; }); }

function plantKind() { return $("plant-seesaw").checked ? "seesaw" : "pendulum"; }

// The controller file chosen for the seesaw: its name and text (read in the page, sent with the form).
let sfFile = null;

function controllerForm() {
  if (plantKind() === "seesaw") {
    return { plant: "seesaw", mode: $("sf-mode-file").checked ? "file" : "lqr", q: $("sf-q").value, r: $("sf-r").value,
      integral: $("sf-integral").checked, file: sfFile || { name: "", text: "" } };
  }
  const mode = $("mode-pid").checked ? "pid" : "kernel";
  return {
    plant: "pendulum",
    mode,
    zeros: $("k-zeros").value, poles: $("k-poles").value, gain: $("k-gain").value,
    compensators: compRows().map((tr) => ({
      zeros: tr.querySelector(".c-zeros").value, poles: tr.querySelector(".c-poles").value, gain: tr.querySelector(".c-gain").value,
    })),
    pid: { kp: $("pid-kp").value, ki: $("pid-ki").value, kd: $("pid-kd").value, pole: $("pid-pole").value },
  };
}

function readForm() {
  return {
    plant: plantKind(),
    controller: controllerForm(),
    pendulum: $("pendulum").value, cart: $("cart").value, calibration: $("calibration").value,
    poke: { magnitude: $("poke-mag").value, duration: $("poke-dur").value, start: $("poke-start").value },
    stop_time: $("stop-time").value, step: $("step").value, method: $("method").value,
    delay: $("delay").value, quantization: $("quantization").checked,
    recentre: $("recentre").checked, swing_up: $("swing-up").checked,
  };
}

function debounce(fn, ms) {
  let timer = null;
  return (...args) => { clearTimeout(timer); timer = setTimeout(() => fn(...args), ms); };
}

let checkSerial = 0;
async function checkController() {
  const serial = ++checkSerial;
  const answer = await api("/api/controller", controllerForm());
  if (serial !== checkSerial) return;  // typed on meanwhile: an older answer must not overwrite
  const el = $("controller-status");
  if (answer.ok && answer.K) {
    const poles = answer.closed_loop_poles.map(([re, im]) => (im ? `${re.toPrecision(4)}${im >= 0 ? "+" : "−"}${Math.abs(im).toPrecision(4)}j` : re.toPrecision(4)));
    setStatus(el, true, `V = −K·[${answer.states.join(", ")}]\n` + answer.states.map((s, k) => `K_${s} = ${Number(answer.K[k].toPrecision(6))}`).join("\n") +
      `\nclosed-loop poles (linear model): ${poles.join(", ")}`);
    updateLinear();
  } else if (answer.ok) {
    setStatus(el, true, `Gc(s) = ${answer.describe}\n` + answer.factors.map((f, k) => `G${k + 1} (${f.label}) = ${f.text}`).join("\n"));
    updateLinear();
  } else {
    setStatus(el, false, answer.error);
  }
}
const controllerChanged = debounce(checkController, 250);

// ------------------------------------------------------------------------------------ linear view
let linearSerial = 0;
const updateLinear = debounce(async () => {
  const serial = ++linearSerial;
  const answer = await api("/api/linear", readForm());
  if (serial !== linearSerial) return;
  const Plotly = await loadPlotly();
  if (!answer.ok) { $("margins").textContent = answer.error; return; }
  if (answer.seesaw) { drawSeesawPoles(Plotly, answer); return; }
  const traces = answer.branches.map((b, j) => ({ x: b.re, y: b.im, mode: "lines", line: { color: "#1f77b4" }, name: "root locus", showlegend: j === 0 }));
  traces.push({ x: answer.open_poles.re, y: answer.open_poles.im, mode: "markers", marker: { symbol: "x", size: 11, color: "#d62728" }, name: "open-loop poles" });
  traces.push({ x: answer.open_zeros.re, y: answer.open_zeros.im, mode: "markers", marker: { symbol: "circle-open", size: 11, color: "#2ca02c" }, name: "open-loop zeros" });
  traces.push({ x: answer.closed_poles.re, y: answer.closed_poles.im, mode: "markers", marker: { symbol: "square", size: 9, color: answer.stable ? "#ff7f0e" : "#d62728", line: { color: "#000", width: 1 } }, name: "closed-loop poles" });
  const [lo, hi, half] = answer.view;
  Plotly.react("rootlocus", traces, {
    title: { text: "root locus of Lp·C(s)·G(s)", font: { size: 13 }, x: 0.01, xanchor: "left" }, margin: { t: 30, r: 10, b: 40, l: 50 },
    xaxis: { title: { text: "σ (1/s)" }, range: [lo, hi], zeroline: true }, yaxis: { title: { text: "ω (rad/s)" }, range: [-half, half] },
    legend: { font: { size: 10 } },
  }, { responsive: true, displaylogo: false });
  const b = answer.bode;
  // The margins drawn where they are read: at the gain crossover (phase margin) and phase crossover (gain margin).
  const marks = [];
  if (b.gain_crossover_rad_s) marks.push({ type: "line", xref: "x", yref: "paper", x0: b.gain_crossover_rad_s, x1: b.gain_crossover_rad_s, y0: 0, y1: 1, line: { dash: "dash", color: "#2ca02c" } });
  if (b.phase_crossover_rad_s) marks.push({ type: "line", xref: "x", yref: "paper", x0: b.phase_crossover_rad_s, x1: b.phase_crossover_rad_s, y0: 0, y1: 1, line: { dash: "dot", color: "#d62728" } });
  Plotly.react("bode", [
    { x: b.omega, y: b.mag_db, name: "|L| (dB)", line: { color: "#1f77b4" } },
    { x: b.omega, y: b.phase_deg, name: "phase (°)", yaxis: "y2", line: { color: "#ff7f0e" } },
  ], {
    title: { text: "Bode plot of the loop", font: { size: 13 }, x: 0.01, xanchor: "left" }, margin: { t: 30, r: 10, b: 40, l: 50 }, showlegend: false,
    grid: { rows: 2, columns: 1 },
    xaxis: { type: "log", title: { text: "ω (rad/s)" } },
    yaxis: { title: { text: "dB" }, domain: [0.55, 1] }, yaxis2: { title: { text: "deg" }, domain: [0, 0.45], anchor: "x" },
    shapes: marks,
  }, { responsive: true, displaylogo: false });
  const f = (v, u) => `${Number(v).toPrecision(3)} ${u}`;
  const gm = b.gain_margin_db === null ? "gain margin: none (the phase never crosses -180°)" : `gain margin ${f(b.gain_margin_db, "dB")} at ${f(b.phase_crossover_rad_s, "rad/s")} (red dotted)`;
  const pm = b.phase_margin_deg === null ? "phase margin: none (|L| never crosses 0 dB)" : `phase margin ${f(b.phase_margin_deg, "°")} at ${f(b.gain_crossover_rad_s, "rad/s")} (green dashed)`;
  $("margins").textContent = `${gm}; ${pm}` +
    (answer.unstable_open_loop_poles ? ` (the open loop has ${answer.unstable_open_loop_poles} unstable pole(s): read stability from the closed-loop poles, not from the margins alone)` : "");
  $("linear-verdict").textContent = (answer.stable ? "closed loop stable" : "closed loop UNSTABLE") +
    `; sampled loop with delay: ${answer.sampled_stable ? "stable" : "UNSTABLE"} (max |z| = ${answer.sampled_max_abs_z.toFixed(5)})`;
  $("linear-never").textContent = answer.never ? `Before you run it: ${answer.never}.` : "";
}, 300);

// The seesaw's state feedback has no single loop to draw a root locus or a Bode plot of: its poles, open and closed.
function drawSeesawPoles(Plotly, answer) {
  const [lo, hi, half] = answer.view;
  Plotly.react("rootlocus", [
    { x: answer.open_poles.re, y: answer.open_poles.im, mode: "markers", marker: { symbol: "x", size: 11, color: "#d62728" }, name: "open loop (the seesaw alone)" },
    { x: answer.closed_poles.re, y: answer.closed_poles.im, mode: "markers", marker: { symbol: "square", size: 9, color: answer.stable ? "#ff7f0e" : "#d62728", line: { color: "#000", width: 1 } }, name: "with the state feedback" },
  ], {
    title: { text: "poles of the seesaw's linear model", font: { size: 13 }, x: 0.01, xanchor: "left" }, margin: { t: 30, r: 10, b: 40, l: 50 },
    xaxis: { title: { text: "σ (1/s)" }, range: [lo, hi], zeroline: true }, yaxis: { title: { text: "ω (rad/s)" }, range: [-half, half] },
    legend: { font: { size: 10 } },
  }, { responsive: true, displaylogo: false });
  Plotly.purge("bode");
  $("bode").innerHTML = "";
  $("margins").textContent = `the seesaw alone has ${answer.unstable_open_loop_poles} unstable pole(s); a state feedback has no single loop, so no Bode plot or margins`;
  $("linear-verdict").textContent = answer.stable ? "closed loop stable (continuous linear model)" : "closed loop UNSTABLE (continuous linear model)";
  $("linear-never").textContent = "";
}

// ------------------------------------------------------------------------------------ runs
const runs = new Map();   // id -> {summary, data, shown, color}
let current = null;

function renderRuns() {
  const body = document.querySelector("#runs tbody");
  body.innerHTML = "";
  for (const [id, run] of runs) {
    const tr = document.createElement("tr");
    tr.dataset.run = id;
    if (id === current) tr.className = "current";
    tr.innerHTML = `<td><input type="checkbox" class="show"${run.shown ? " checked" : ""}${run.data ? "" : " disabled"}></td>` +
      `<td class="label"><span style="color:${run.color}">■</span> </td><td class="state"></td>`;
    tr.querySelector(".label").append(run.summary.label);
    tr.querySelector(".state").textContent = run.summary.state;
    tr.querySelector(".show").onchange = (e) => { run.shown = e.target.checked; drawResults(); };
    tr.querySelector(".label").onclick = () => { if (run.data) { current = id; run.shown = true; renderRuns(); drawResults(); } };
    body.appendChild(tr);
  }
}

async function addRun(summary) {
  const run = { summary, data: null, shown: true, color: COLORS[runs.size % COLORS.length] };
  runs.set(summary.id, run);
  renderRuns();
  return run;
}

async function loadRunData(run) {
  const data = await api(`/api/runs/${run.summary.id}/data`);
  if (!data.ok) throw new Error(data.error);
  run.data = data;
  current = run.summary.id;
  renderRuns();
  await drawResults();
}

async function startRun() {
  const status = $("run-status");
  status.className = "status"; status.textContent = "";
  const answer = await api("/api/run", readForm());
  if (!answer.ok) { setStatus(status, false, answer.error); return; }
  const run = await addRun(answer.run);
  $("run").disabled = true;
  $("progress").value = 0;
  $("progress-text").textContent = "starting the simulation…";
  $("progress-box").hidden = false;
  try {
    for (;;) {
      await new Promise((r) => setTimeout(r, 250));
      const s = await api(`/api/runs/${run.summary.id}`);
      if (!s.ok) { setStatus(status, false, s.error); break; }
      run.summary = s.run;
      $("progress").value = s.run.stop_time ? s.run.progress / s.run.stop_time : 0;
      $("progress-text").textContent = `simulated ${s.run.progress.toFixed(1)} / ${s.run.stop_time} s`;
      if (s.run.state === "error") { setStatus(status, false, s.run.error); renderRuns(); break; }
      if (s.run.state === "done") {
        await loadRunData(run);
        const v = verdictStatus(run.data.metrics);
        setStatus(status, v.ok, `${v.text}\nresults in ${s.run.folder}`);
        break;
      }
    }
  } finally {
    $("run").disabled = false;
    $("progress-box").hidden = true;
  }
}

async function openFolder() {
  const answer = await api("/api/open", { path: $("open-path").value });
  if (!answer.ok) { setStatus($("open-status"), false, answer.error); return; }
  const run = await addRun(answer.run);
  try {
    await loadRunData(run);
    setStatus($("open-status"), true, `opened ${run.data.label}`);
  } catch (err) {
    setStatus($("open-status"), false, err.message);
  }
}

// ------------------------------------------------------------------------------------ results
function fmt(v) {
  if (v === null || v === undefined) return "n/a";
  if (typeof v === "object" && v.outcome) {
    const outcome = v.plant === "seesaw" && v.outcome === "balanced" ? "held" : v.outcome;  // the seesaw is held, not balanced
    return outcome + (v.warnings.length ? ` (${v.warnings.map((w) => w.kind).join(", ")})` : "");
  }
  if (typeof v === "boolean") return v ? "yes" : "no";
  if (typeof v === "number") return Number(v.toPrecision(4)).toString();
  return String(v);
}

// The angle of a run: the pendulum's alpha or the seesaw's tilt theta.
function angleOf(data) { return data.columns.alpha || data.columns.theta; }

async function drawResults() {
  const shown = [...runs.values()].filter((r) => r.shown && r.data);
  const seesaw = shown.length > 0 && shown.every((r) => r.data.plant === "seesaw");
  drawMetrics(shown);
  drawDownloads();
  drawFrame(0);
  const Plotly = await loadPlotly();
  const panels = seesaw ? [["angle", "tilt (°)", 180 / Math.PI], ["x", "cart (cm)", 100], ["voltage", "voltage (V)", 1]]
    : [["angle", "angle (°)", 180 / Math.PI], ["tip", "tip (cm)", 100], ["x", "cart (cm)", 100], ["voltage", "voltage (V)", 1]];
  const traces = [];
  shown.forEach((run) => {
    const t = run.data.columns.t.map((v) => v - run.data.poke_start);
    panels.forEach(([key, , scale], k) => {
      const y = key === "angle" ? angleOf(run.data) : run.data.columns[key];
      if (!y) return;
      traces.push({ x: t, y: y.map((v) => v * scale), name: run.data.label, legendgroup: run.summary.id, showlegend: k === 0,
        line: { color: run.color, width: 1.3 }, xaxis: "x", yaxis: k === 0 ? "y" : `y${k + 1}` });
    });
  });
  const word = seesaw ? "tap" : "poke";
  const layout = { margin: { t: 30, r: 10, b: 40, l: 60 }, title: { text: `response (time from the ${word})`, font: { size: 13 }, x: 0.01, xanchor: "left" },
    grid: { rows: panels.length, columns: 1, shared_xaxes: true }, legend: { orientation: "h", y: -0.08 }, xaxis: { title: { text: `t − t_${word} (s)` } } };
  const share = 1 / panels.length;
  panels.forEach(([, title], k) => {
    layout[k === 0 ? "yaxis" : `yaxis${k + 1}`] = { title: { text: title }, domain: [1 - (k + 1) * share + 0.03, 1 - k * share] };
  });
  Plotly.react("response", traces, layout, { responsive: true, displaylogo: false });
  const zoom = shown.map((run) => ({
    x: run.data.columns.t.map((v) => v - run.data.poke_start), y: angleOf(run.data).map((v) => v * 180 / Math.PI),
    name: run.data.label, line: { color: run.color },
  }));
  const what = seesaw ? "tilt" : "angle";
  Plotly.react("zoom", zoom, { title: { text: `${what} at the ${word} (zoom)`, font: { size: 13 }, x: 0.01, xanchor: "left" }, margin: { t: 30, r: 10, b: 40, l: 50 },
    showlegend: false, xaxis: { range: [-0.2, seesaw ? 4.0 : 2.0], title: { text: `t − t_${word} (s)` } }, yaxis: { title: { text: `${what} (°)` } } },
  { responsive: true, displaylogo: false });
}

function drawMetrics(shown) {
  const table = $("metrics");
  table.innerHTML = "";
  if (!shown.length) return;
  const head = document.createElement("tr");
  head.innerHTML = "<th>metric</th>";
  shown.forEach((run) => { const th = document.createElement("th"); th.style.color = run.color; th.textContent = run.data.label; head.appendChild(th); });
  table.appendChild(head);
  // The rows of the plants shown: the pendulum's, the seesaw's, or both (each key once).
  const plants = new Set(shown.map((run) => run.data.plant || "pendulum"));
  const rows = [...(plants.has("pendulum") ? METRICS : []), ...(plants.has("seesaw") ? SEESAW_METRICS : [])]
    .filter((row, k, all) => all.findIndex((other) => other[0] === row[0]) === k);
  for (const [key, label, unit, scale] of rows) {
    const tr = document.createElement("tr");
    tr.innerHTML = `<th>${label}${unit ? " (" + unit + ")" : ""}</th>`;
    shown.forEach((run) => {
      const td = document.createElement("td");
      const value = run.data.metrics[key];
      td.dataset.run = run.summary.id; td.dataset.key = key;
      td.dataset.value = value === undefined ? "" : JSON.stringify(value);
      td.textContent = fmt(typeof value === "number" && scale ? value * scale : value);
      const why = (run.data.metrics.not_reported || {})[key];
      if (why) { td.title = why; td.textContent += " *"; }
      if (key === "verdict" && value) td.className = value.clean ? "ok" : value.outcome === "balanced" ? "warn" : "error";
      tr.appendChild(td);
    });
    table.appendChild(tr);
  }
  // Why a metric is not reported, in words (the table marks it with *).
  const notes = $("metrics-notes");
  notes.innerHTML = "";
  shown.forEach((run) => {
    const reasons = run.data.metrics.not_reported || {};
    new Set(Object.values(reasons)).forEach((why) => {
      const keys = Object.keys(reasons).filter((k) => reasons[k] === why).map((k) => (rows.find((m) => m[0] === k) || [k, k])[1]);
      const line = document.createElement("div");
      line.textContent = `* ${run.data.label}: ${keys.join(", ")} not reported: ${why}`;
      notes.appendChild(line);
    });
  });
}

function drawDownloads() {
  const box = $("downloads");
  box.innerHTML = "";
  const run = runs.get(current);
  if (!run || !run.data) return;
  const add = (name) => {
    const a = document.createElement("a");
    a.href = `/files/${run.summary.id}/${name}`; a.download = name; a.textContent = name; a.className = "download";
    box.appendChild(a);
  };
  run.data.files.forEach(add);
  if (run.summary.kind === "sim" && !run.data.files.some((f) => f.endsWith(".png"))) {
    const b = document.createElement("button");
    b.textContent = "make PNG plots"; b.id = "make-plots";
    b.onclick = async () => {
      b.disabled = true;
      const answer = await api(`/api/runs/${run.summary.id}/plots`);
      if (answer.ok) { run.data.files = [...new Set([...run.data.files, ...answer.files])].sort(); drawDownloads(); } else { b.textContent = answer.error; }
    };
    box.appendChild(b);
  }
}

// ------------------------------------------------------------------------------------ the rig's animation
let animTimer = null;
function drawFrame(i) {
  const run = runs.get(current);
  const canvas = $("anim");
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (!run || !run.data) return;
  if (run.data.plant === "seesaw") { drawSeesaw(ctx, canvas, run.data.columns, i); return; }
  const c = run.data.columns;
  const scale = 400;  // px per m: the track is about +-0.5 m
  const x0 = canvas.width / 2, y0 = canvas.height - 50;
  ctx.strokeStyle = "#888"; ctx.lineWidth = 3;
  ctx.beginPath(); ctx.moveTo(x0 - 0.5 * scale, y0 + 14); ctx.lineTo(x0 + 0.5 * scale, y0 + 14); ctx.stroke();
  const x = c.x ? c.x[i] : 0, alpha = c.alpha[i];
  const L = Math.max(0.2, Math.min(0.7, run.data.Lp || 0.64)) * 250;
  const cx = x0 + x * scale;
  ctx.fillStyle = "#345"; ctx.fillRect(cx - 25, y0 - 10, 50, 24);
  ctx.strokeStyle = "#c33"; ctx.lineWidth = 5;
  ctx.beginPath(); ctx.moveTo(cx, y0); ctx.lineTo(cx + L * Math.sin(alpha), y0 - L * Math.cos(alpha)); ctx.stroke();
  $("anim-time").textContent = `t = ${c.t[i].toFixed(2)} s, angle ${(alpha * 180 / Math.PI).toFixed(2)}°`;
}

// The seesaw as pendulab.analysis.animation.animate_seesaw draws it: the track 0.125 m above the pivot, tilted by theta
// (positive: the +x end up), the cart on it at x.
function drawSeesaw(ctx, canvas, c, i) {
  const scale = 400, height = 0.125, half = 0.45;
  const px = canvas.width / 2, py = canvas.height - 60;
  const theta = c.theta[i], x = c.x ? c.x[i] : 0;
  const at = (s, h) => [px + scale * (s * Math.cos(theta) - h * Math.sin(theta)), py - scale * (s * Math.sin(theta) + h * Math.cos(theta))];
  ctx.fillStyle = "#888";
  ctx.beginPath(); ctx.moveTo(px, py); ctx.lineTo(px - 20, py + 40); ctx.lineTo(px + 20, py + 40); ctx.closePath(); ctx.fill();
  ctx.strokeStyle = "#555"; ctx.lineWidth = 4;
  ctx.beginPath(); ctx.moveTo(px, py); ctx.lineTo(...at(0, height)); ctx.stroke();
  ctx.strokeStyle = "#345"; ctx.lineWidth = 5;
  ctx.beginPath(); ctx.moveTo(...at(-half, height)); ctx.lineTo(...at(half, height)); ctx.stroke();
  const [cx, cy] = at(x, height + 0.03);
  ctx.save(); ctx.translate(cx, cy); ctx.rotate(-theta);
  ctx.fillStyle = "#c33"; ctx.fillRect(-22, -10, 44, 20);
  ctx.restore();
  $("anim-time").textContent = `t = ${c.t[i].toFixed(2)} s, tilt ${(theta * 180 / Math.PI).toFixed(2)}°, cart ${(x * 100).toFixed(1)} cm`;
}

function play() {
  const run = runs.get(current);
  if (!run || !run.data) return;
  clearInterval(animTimer);
  const t = run.data.columns.t;
  const start = performance.now();
  let i = 0;
  animTimer = setInterval(() => {
    const now = t[0] + (performance.now() - start) / 1000;
    while (i < t.length - 1 && t[i] < now) i++;
    drawFrame(i);
    if (i >= t.length - 1) clearInterval(animTimer);
  }, 33);
}

// ------------------------------------------------------------------------------------ calibration
async function loadCalibrations(select) {
  const answer = await api("/api/calibrations");
  if (!answer.ok) return;
  const el = $("calibration");
  el.innerHTML = "";
  answer.calibrations.forEach((c) => { const o = document.createElement("option"); o.value = c.key; o.textContent = c.label; el.appendChild(o); });
  if (select) el.value = select;
}

async function uploadCalibration() {
  const file = $("cal-file").files[0];
  const status = $("cal-status");
  if (!file) return;
  if (file.size > MAX_UPLOAD) {
    setStatus(status, false, `${file.name} is ${(file.size / 1e6).toFixed(1)} MB; a calibration file is at most 1 MB (the lab's are a few kB): is it the right file?`);
    $("cal-file").value = "";
    return;
  }
  let answer;
  try {
    const response = await fetch("/api/calibration", { method: "POST", body: file,
      headers: { "X-Pendulab-Tab": TAB, "X-Filename": encodeURIComponent(file.name), "Content-Type": "application/octet-stream" } });
    answer = await response.json();
  } catch (err) {
    answer = { ok: false, error: `${file.name} could not be sent: ${err.message}` };
  }
  $("cal-file").value = "";
  if (!answer.ok) { setStatus(status, false, answer.error); return; }
  await loadCalibrations(answer.key);
  setStatus(status, true, `${answer.label} loaded and selected`);
  updateLinear();
}

// ------------------------------------------------------------------------------------ start
function fillDemo() {
  $("mode-kernel").checked = true; modeChanged();
  $("k-zeros").value = "-5"; $("k-poles").value = "7"; $("k-gain").value = "40000";
  compRows().forEach((tr) => tr.remove());
  addCompensator(["-17", "-80", ""]);
  addCompensator(["", "-80", ""]);
  checkController();
}

function fillSeesawDemo() {
  $("sf-mode-lqr").checked = true; sfModeChanged();
  $("sf-q").value = "1000,5000,0,0,2000"; $("sf-r").value = "0.5"; $("sf-integral").checked = true; integralChanged();
}

function sfModeChanged() {
  const file = $("sf-mode-file").checked;
  $("sf-file-entry").hidden = !file; $("sf-lqr-entry").hidden = file;
  controllerChanged();
}

function integralChanged() {
  $("sf-states").textContent = $("sf-integral").checked ? "x, θ, ẋ, θ̇, ∫θ" : "x, θ, ẋ, θ̇";
  controllerChanged();
}

function readControllerFile() {
  const file = $("sf-file").files[0];
  if (!file) { sfFile = null; controllerChanged(); return; }
  if (file.size > MAX_UPLOAD) {
    sfFile = null;
    setStatus($("controller-status"), false, `${file.name} is ${(file.size / 1e6).toFixed(1)} MB; a controller file is a few hundred bytes: is it the right file?`);
    return;
  }
  const reader = new FileReader();
  reader.onload = () => { sfFile = { name: file.name, text: String(reader.result) }; checkController(); };
  reader.onerror = () => { sfFile = null; setStatus($("controller-status"), false, `${file.name} could not be read`); };
  reader.readAsText(file);
}

// The plant chosen: the controller entry, the plant's fields and the disturbance's words and defaults follow it.
function plantChanged() {
  const kind = plantKind();
  const seesaw = kind === "seesaw";
  $("tf-controller").hidden = seesaw; $("sf-controller").hidden = !seesaw;
  ["pendulum-label", "cart-label", "recentre-label", "swing-up-label"].forEach((id) => { $(id).hidden = seesaw; });
  const [word, magnitude, duration] = DISTURBANCE[kind];
  const [, otherMagnitude, otherDuration] = DISTURBANCE[seesaw ? "pendulum" : "seesaw"];
  document.querySelectorAll(".disturbance").forEach((el) => { el.textContent = word; });
  // The other plant's defaults become this one's; typed values stay.
  if ($("poke-mag").value === otherMagnitude) $("poke-mag").value = magnitude;
  if ($("poke-dur").value === otherDuration) $("poke-dur").value = duration;
  $("bode").dataset.hint = seesaw ? "a state feedback has no single loop: no Bode plot" : "and the Bode plot of the loop here";
  checkController();
}

function modeChanged() {
  const pid = $("mode-pid").checked;
  $("pid-entry").hidden = !pid; $("kernel-entry").hidden = pid;
  controllerChanged();
}

// A reload keeps the tab's runs: the tab id lives in sessionStorage and the server lists the tab's runs.
async function restoreRuns() {
  const answer = await api("/api/runs");
  if (!answer.ok) return;
  for (const summary of answer.runs) {
    if (runs.has(summary.id)) continue;
    const run = await addRun(summary);
    if (summary.state === "done") {
      try { await loadRunData(run); } catch (err) { /* listed; its data is gone */ }
    }
  }
}

function init() {
  ["k-zeros", "k-poles", "k-gain", "pid-kp", "pid-ki", "pid-kd", "pid-pole"].forEach((id) => $(id).addEventListener("input", controllerChanged));
  ["mode-kernel", "mode-pid"].forEach((id) => $(id).addEventListener("change", modeChanged));
  ["plant-pendulum", "plant-seesaw"].forEach((id) => $(id).addEventListener("change", plantChanged));
  ["sf-mode-lqr", "sf-mode-file"].forEach((id) => $(id).addEventListener("change", sfModeChanged));
  ["sf-q", "sf-r"].forEach((id) => $(id).addEventListener("input", controllerChanged));
  $("sf-integral").addEventListener("change", integralChanged);
  $("sf-file").addEventListener("change", readControllerFile);
  $("sf-demo").onclick = fillSeesawDemo;
  ["pendulum", "cart", "calibration", "method", "delay", "step"].forEach((id) => $(id).addEventListener("change", updateLinear));
  $("add-comp").onclick = () => addCompensator();
  $("demo").onclick = fillDemo;
  $("run").onclick = startRun;
  $("open-btn").onclick = openFolder;
  $("play").onclick = play;
  $("cal-file").addEventListener("change", uploadCalibration);
  loadCalibrations();
  restoreRuns();
  requestAnimationFrame(() => { document.body.dataset.drawn = "1"; });
  loadPlotly().then(() => { document.body.dataset.plotly = "1"; });
}

document.addEventListener("DOMContentLoaded", init);
