// ASLM dashboard: the fleet table (#/) and a page per bus (#/bus/<name>), polling the service's REST API.
// No build step and no framework: the service serves this file as it is, offline; charts are uPlot.
"use strict";
(() => {
  const PARAMS = ["a", "b", "H2", "Tm"];
  const UNITS = { a: "1/s", b: "1/s", H2: "s", Tm: "pu" };
  const STATES = ["ok", "stale", "failed", "skipped", "pending"];
  const VERDICTS = ["explained", "ambiguous", "unexplained", "consistent", "failed"];
  const SPANS = [[3600, "1 h"], [6 * 3600, "6 h"], [86400, "24 h"], [7 * 86400, "7 d"], [30 * 86400, "30 d"]];
  const ui = {
    timer: null, busy: false, again: false, charts: {}, bus: null, span: 86400,
    fleet: { q: "", state: [], verdict: [], sort: "bus", desc: false, offset: 0, limit: 100 },
  };
  const $ = (sel) => document.querySelector(sel);

  function el(tag, attrs, ...kids) {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (k === "class") e.className = v;
      else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
      else if (k === "dataset") Object.assign(e.dataset, v);
      else e.setAttribute(k, v);
    }
    for (const k of kids.flat()) if (k !== null && k !== undefined) e.append(k instanceof Node ? k : String(k));
    return e;
  }

  // Bus names may hold "/" (sharded names): the REST paths take them as they are, segment by segment.
  const busPath = (bus) => bus.split("/").map(encodeURIComponent).join("/");

  async function getJSON(url, allow404) {
    const r = await fetch(url, { cache: "no-store" });
    if (allow404 && (r.status === 404 || r.status === 503 || r.status === 422)) return { _status: r.status, ...(await r.json()) };
    if (!r.ok) throw new Error(`${url}: HTTP ${r.status} ${(await r.text()).slice(0, 200)}`);
    return r.json();
  }

  function fmt(v) {
    if (v === null || v === undefined || Number.isNaN(v)) return "–";
    const a = Math.abs(v);
    return a !== 0 && (a >= 1e4 || a < 1e-3) ? v.toExponential(2) : v.toPrecision(4);
  }
  function ago(s) {
    if (s === null || s === undefined) return "–";
    if (s < 90) return `${s.toFixed(0)} s`;
    if (s < 5400) return `${(s / 60).toFixed(0)} min`;
    if (s < 172800) return `${(s / 3600).toFixed(1)} h`;
    return `${(s / 86400).toFixed(1)} d`;
  }
  const utc = (t) => (t === null || t === undefined ? "–" : new Date(t * 1000).toISOString().slice(0, 19).replace("T", " ") + "Z");
  const staticText = (st) => (st ? Object.entries(st).map(([k, v]) => `${k} ${fmt(v)}`).join("  ") : "–");
  // The static part as ambient data identify it: P0, Q0 at the window's mean voltage V0 and their local voltage
  // exponents kpv, kqv.  The Z/I/P split is shown beside it only where the window separates it: with V moving by
  // tenths of a percent [1, V, V²] are nearly collinear and the split's coefficients are noise (the identifier's
  // flag static_split_unidentifiable), while P0 and dP/dV are not (docs/numerics.md).
  const SPLIT_FLAG = "static_split_unidentifiable";
  const hasLocal = (loc) => Boolean(loc) && loc.P0 !== undefined && loc.P0 !== null;
  const localText = (loc) => `P0 ${fmt(loc.P0)} kpv ${fmt(loc.kpv)} · Q0 ${fmt(loc.Q0)} kqv ${fmt(loc.kqv)}`;
  const withSe = (v, se) => `${fmt(v)} ± ${fmt(se)}`;
  function staticCell(st, loc, flags) {
    if (!hasLocal(loc)) return staticText(st);  // results stored before static_local existed
    const split = flags.includes(SPLIT_FLAG);
    return el("span", { class: "static", dataset: { split: split ? "unidentifiable" : "identifiable" },
      title: (split ? "Z/I/P split not identifiable from this window: " : "") + staticText(st) },
    localText(loc), split ? "" : el("span", { class: "se" }, `  ${staticText(st)}`));
  }
  function staticRows(par) {
    if (!par || !hasLocal(par.static_local)) return [["static", staticText(par && par.static)]];
    const loc = par.static_local, se = par.static_stderr || {};
    const split = par.flags.includes(SPLIT_FLAG);
    return [
      [`static P at V0 = ${fmt(loc.V0)} pu`, `P0 ${withSe(loc.P0, loc.P0_se)} · dP/dV ${withSe(loc.dPdV, loc.dPdV_se)} · kpv ${withSe(loc.kpv, loc.kpv_se)}`],
      [`static Q at V0`, `Q0 ${withSe(loc.Q0, loc.Q0_se)} · dQ/dV ${withSe(loc.dQdV, loc.dQdV_se)} · kqv ${withSe(loc.kqv, loc.kqv_se)}`],
      ["static split", el("span", { id: "static-split", dataset: { split: split ? "unidentifiable" : "identifiable" } },
        Object.entries(par.static).map(([k, v]) => `${k} ${withSe(v, se[k])}`).join("  "),
        split ? el("span", { class: "muted" }, " — not identifiable from this window (static_split_unidentifiable)") : "")],
    ];
  }

  function showError(err) {
    const box = $("#error");
    box.hidden = !err;
    box.textContent = err ? String(err.message || err) : "";
  }

  // --- header: instance, T, periods -----------------------------------------------------------------
  async function refreshHeader() {
    const h = await getJSON("/health");
    $("#instance").textContent = h.instance;
    const last = h.last_period;
    $("#run-state").textContent = `T = ${h.period_s} s · ${h.running_period ? "computing period " + utc(h.running_period) : "next period " + utc(h.next_period)}` +
      (last ? ` · last: ${last.n_ok} ok, ${last.n_failed} failed, ${last.n_skipped} skipped in ${last.latency_s.toFixed(1)} s` : "");
    return h;
  }

  // --- fleet table -------------------------------------------------------------------------------------
  const COLUMNS = [
    { label: "bus", sort: "bus", cls: "txt", cell: (r) => el("a", { href: `#/bus/${encodeURIComponent(r.bus)}` }, r.bus) },
    { label: "state", sort: "state", cls: "txt", cell: (r) => el("span", { class: `state ${r.state}`, title: r.reason || "" }, r.state) },
    ...PARAMS.map((k) => ({
      label: `${k} [${UNITS[k]}]`, sort: k,
      cell: (r) => (r.dynamic ? [fmt(r.dynamic[k]), el("span", { class: "se" }, ` ±${fmt(r.stderr && r.stderr[k])}`)] : "–"),
    })),
    { label: "static at V0", cls: "txt static-col", cell: (r) => staticCell(r.static, r.static_local, r.flags),
      title: "P0, Q0: static power at the mean voltage V0 [pu]; kpv, kqv: local voltage exponents (V0/P0)·dP/dV [-]; " +
        "the Z/I/P split is shown only where the window identifies it" },
    { label: "fd P", sort: "fd_p", cell: (r) => fmt(r.fit && r.fit.fd_p) },
    { label: "fd Q", sort: "fd_q", cell: (r) => fmt(r.fit && r.fit.fd_q) },
    { label: "flags", sort: "flags", cls: "flags", cell: (r) => r.flags.join(" ") },
    { label: "age", sort: "age_s", cell: (r) => ago(r.age_s) },
    { label: "diagnosis", sort: "verdict", cls: "txt v", cell: (r) => r.verdict ? [el("span", { class: `verdict ${r.verdict}` }, r.verdict), r.cause ? ` (${r.cause})` : ""] : "–" },
  ];

  function chipGroup(kind, names) {
    return names.map((n) => el("span", {
      class: "chip", dataset: { kind, name: n },
      onclick: () => {
        const list = ui.fleet[kind];
        const i = list.indexOf(n);
        if (i >= 0) list.splice(i, 1); else list.push(n);
        ui.fleet.offset = 0;
        refreshNow();
      },
    }, n, el("b", {}, "0")));
  }

  function renderFleet() {
    const f = ui.fleet;
    let typing = null;
    const head = el("tr", {}, COLUMNS.map((c) => el("th", {
      class: c.cls || "", dataset: { sort: c.sort || "" }, ...(c.title ? { title: c.title } : {}),
      onclick: () => {
        if (!c.sort) return;
        f.desc = f.sort === c.sort ? !f.desc : false;
        f.sort = c.sort;
        refreshNow();
      },
    }, c.label)));
    $("#view").replaceChildren(
      el("div", { class: "toolbar" },
        el("input", { type: "search", id: "q", placeholder: "filter buses", value: f.q, oninput: (e) => {
          clearTimeout(typing);
          typing = setTimeout(() => { f.q = e.target.value; f.offset = 0; refreshNow(); }, 250);
        } }),
        chipGroup("state", STATES), el("span", { class: "muted" }, "diagnosis:"), chipGroup("verdict", VERDICTS)),
      el("table", { id: "fleet" }, el("thead", {}, head), el("tbody")),
      el("div", { class: "pager" },
        el("button", { id: "prev", onclick: () => { f.offset = Math.max(0, f.offset - f.limit); refreshNow(); } }, "◀"),
        el("span", { id: "page" }),
        el("button", { id: "next", onclick: () => { f.offset += f.limit; refreshNow(); } }, "▶"),
        el("select", { id: "limit", onchange: (e) => { f.limit = +e.target.value; f.offset = 0; refreshNow(); } },
          [50, 100, 200, 500].map((n) => el("option", n === f.limit ? { value: n, selected: "" } : { value: n }, `${n} / page`)))));
  }

  async function refreshFleet() {
    const f = ui.fleet;
    const p = new URLSearchParams({ q: f.q, sort: f.sort, desc: f.desc, offset: f.offset, limit: f.limit });
    f.state.forEach((s) => p.append("state", s));
    f.verdict.forEach((v) => p.append("verdict", v));
    const [page] = await Promise.all([getJSON(`/fleet?${p}`), refreshHeader()]);
    if (!$("#fleet")) return;
    if (page.matched && f.offset >= page.matched) { f.offset = Math.floor((page.matched - 1) / f.limit) * f.limit; return refreshFleet(); }
    for (const chip of document.querySelectorAll(".chip")) {
      const { kind, name } = chip.dataset;
      chip.classList.toggle("on", f[kind].includes(name));
      chip.querySelector("b").textContent = page.counts[kind][name] ?? 0;
    }
    for (const th of document.querySelectorAll("#fleet th")) {
      th.classList.toggle("sorted", th.dataset.sort === f.sort);
      th.classList.toggle("desc", th.dataset.sort === f.sort && f.desc);
    }
    $("#fleet tbody").replaceChildren(...page.rows.map((r) => el("tr", {
      class: `state-${r.state}${r.verdict ? " verdict-" + r.verdict : ""}`, dataset: { bus: r.bus },
    }, COLUMNS.map((c) => el("td", { class: c.cls || "" }, c.cell(r))))));
    Object.assign($("#fleet").dataset, { total: page.total, matched: page.matched, shown: page.rows.length });
    const last = Math.min(page.offset + page.rows.length, page.matched);
    $("#page").textContent = `${page.matched ? page.offset + 1 : 0}–${last} of ${page.matched}` +
      (page.matched !== page.total ? ` (filtered from ${page.total})` : "") + " buses";
    $("#prev").disabled = page.offset === 0;
    $("#next").disabled = last >= page.matched;
  }

  // --- bus page --------------------------------------------------------------------------------------
  function chartCard(id, title) {
    return el("div", { class: "card" }, el("h3", {}, title), el("div", { id, class: "chart", dataset: { points: "0" } }));
  }

  function renderBus(bus) {
    ui.charts = {};
    $("#view").replaceChildren(
      el("h2", {}, el("a", { href: "#/" }, "fleet"), " / ", el("span", { id: "bus-name" }, bus)),
      el("div", { class: "toolbar" }, "history span ",
        el("select", { id: "span", onchange: (e) => { ui.span = +e.target.value; refreshNow(); } },
          SPANS.map(([s, l]) => el("option", s === ui.span ? { value: s, selected: "" } : { value: s }, l))),
        el("span", { class: "muted" }, "bands: ±2 standard errors")),
      el("div", { class: "cards" },
        el("div", { class: "card" }, el("h3", {}, "latest result"), el("dl", { id: "summary", class: "kv" })),
        el("div", { class: "card" }, el("h3", {}, "period and configuration"), el("dl", { id: "state", class: "kv" })),
        PARAMS.map((k) => chartCard(`chart-${k}`, `${k} [${UNITS[k]}] history`)),
        chartCard("chart-P", "P [pu]: measured vs model (newest window)"),
        chartCard("chart-Q", "Q [pu]: measured vs model (newest window)"),
        el("div", { class: "card", style: "grid-column: 1 / -1" }, el("h3", {}, "diagnosis timeline"),
          el("table", { id: "diagnoses" }, el("thead", {}, el("tr", {},
            ["period", "verdict", "cause", "channels", "fd P before → after", "fd Q before → after", "message"]
              .map((h) => el("th", { class: "txt" }, h)))), el("tbody")))));
  }

  // Why a window is uncertain: how much of P and Q the voltage explains, and the load's own fluctuation (issue 20).
  function excitationText(par) {
    const q = (par && par.quality) || {};
    if (q.excitation_share_p == null) return "–";
    const pct = (x) => `${Math.round(100 * x)} %`;
    let text = `V and θ explain ${pct(q.excitation_share_p)} of P's and ${pct(q.excitation_share_q)} of Q's ambient ` +
      `variance; own fluctuation ${fmt(q.own_ratio_p)} of P's ambient std`;
    if (q.own_q_per_p != null) text += `, its ΔQ/ΔP ${fmt(q.own_q_per_p)}`;
    if (q.own_median_hz_p != null && q.own_ratio_p >= 0.3) text += `, half of it below ${fmt(q.own_median_hz_p)} Hz`;
    return el("span", { id: "excitation" }, text);
  }

  function kv(target, pairs) {
    $(target).replaceChildren(...pairs.flatMap(([k, v]) => [el("dt", {}, k), el("dd", {}, v)]));
  }

  // Decimals that tell ticks ``splits`` apart: those of their step (0.0005 → 4, 2.5 → 1, 10 → 0).
  function tickDecimals(splits) {
    const step = splits.length > 1 ? Math.abs(splits[1] - splits[0]) : 0;
    if (!(step > 0)) return 3;
    let d = Math.max(0, Math.ceil(-Math.log10(step) - 1e-9));
    while (d < 12 && Math.abs(step * 10 ** d - Math.round(step * 10 ** d)) > 1e-6 * step * 10 ** d) d++;
    return d;
  }

  // One uPlot per container, created on the first data and then only fed (setData keeps zoom and DOM).
  // ``pad``: half the x span shown around a single point [s] (uPlot 1.6 gives one time point 10^8 s, ~3 years).
  function draw(id, series, data, pad = 60) {
    const box = document.getElementById(id);
    if (!box) return;
    box.dataset.points = String(data[0].length);
    let chart = ui.charts[id];
    if (chart && chart.series.length !== series.length + 1) { chart.destroy(); chart = null; }
    if (!chart) {
      if (!data[0].length) return;
      const opts = {
        width: Math.max(300, box.clientWidth), height: 200, scales: { x: { time: true } },
        tzDate: (ts) => uPlot.tzDate(new Date(ts * 1e3), "Etc/UTC"),  // UTC like every other time shown
        series: [{}, ...series.map((s) => ({ points: { show: true, size: 4 }, spanGaps: false, ...s }))],
        // y ticks with as many decimals as their step needs (uPlot's default keeps 3, so a narrow band of Tm
        // showed 0.672 twice).
        axes: [{}, { values: (u, splits) => splits.map((v) => v.toFixed(tickDecimals(splits))) }],
        // The x span drawn, for the browser test (uPlot applies scales after this call returns).
        hooks: { setScale: [(u, key) => { if (key === "x") box.dataset.xspan = String(u.scales.x.max - u.scales.x.min); }] },
      };
      const band = series.findIndex((s) => s.bandTop);
      if (band >= 0) opts.bands = [{ series: [band + 1, band + 3], fill: "rgba(21,101,192,0.15)" }];
      box.replaceChildren();
      chart = ui.charts[id] = new uPlot(opts, data, box);
    } else {
      chart.setData(data);
    }
    if (data[0].length === 1) chart.setScale("x", { min: data[0][0] - pad, max: data[0][0] + pad });
  }

  function drawHistory(results) {
    const ok = results.filter((r) => r.status === "ok" && r.parameters).sort((x, y) => x.period - y.period);
    const x = ok.map((r) => r.period);
    for (const k of PARAMS) {
      const v = ok.map((r) => r.parameters.dynamic[k]);
      const se = ok.map((r) => (r.parameters.stderr || {})[k]);
      const hi = v.map((y, i) => (se[i] == null ? null : y + 2 * se[i]));
      const lo = v.map((y, i) => (se[i] == null ? null : y - 2 * se[i]));
      draw(`chart-${k}`, [
        { label: "+2 SE", stroke: "rgba(21,101,192,0.3)", points: { show: false }, bandTop: true },
        { label: k, stroke: "#1565c0", width: 2 },
        { label: "−2 SE", stroke: "rgba(21,101,192,0.3)", points: { show: false } },
      ], [x, hi, v, lo], ok.length ? ok[0].period_s : 60);
    }
  }

  function drawPlayback(pb) {
    for (const ch of ["P", "Q"]) {
      const box = document.getElementById(`chart-${ch}`);
      if (pb._status) {  // no model yet, no frames held, or the workers busy: say so, keep the last drawing
        box.dataset.note = pb.detail;
        if (!ui.charts[`chart-${ch}`]) box.textContent = pb.detail;
        continue;
      }
      draw(`chart-${ch}`, [
        { label: "measured", stroke: "#455a64", width: 2, points: { show: false } },
        // Dashed so that measured data a model fits closely stay visible beneath it.
        { label: `model (period ${utc(pb.model_period)})`, stroke: "#e65100", width: 1.5, dash: [6, 4], points: { show: false } },
      ], [pb.t, pb[ch], pb[`${ch}_model`]]);
    }
  }

  async function refreshBus(bus) {
    const b = busPath(bus);
    const since = Date.now() / 1000 - ui.span;
    const [latest, history, diagnoses, health, config, pb] = await Promise.all([
      getJSON(`/buses/${b}/parameters/latest`, true),
      getJSON(`/buses/${b}/parameters?since=${since}&limit=10000`),
      getJSON(`/buses/${b}/diagnoses?limit=100`),
      refreshHeader(), getJSON("/config"),
      getJSON(`/buses/${b}/playback`, true),
    ]);
    if (ui.bus !== bus || !$("#summary")) return;
    const lastOk = history.find((r) => r.status === "ok");
    const par = lastOk ? lastOk.parameters : null;
    const d = diagnoses[0];
    $("#summary").dataset.latestPeriod = latest._status ? "" : String(latest.period);
    kv("#summary", latest._status ? [["status", latest.detail]] : [
      ["status", el("span", { class: `state ${latest.status}` }, latest.status + (latest.reason ? ` (${latest.reason})` : ""))],
      ["period", utc(latest.period)],
      ["age", ago(Date.now() / 1000 - latest.completed_at)],
      ["frames", latest.n_frames + (latest.warm_start ? " · warm start" : "")],
      ...PARAMS.map((k) => [`${k} [${UNITS[k]}]`, par ? `${fmt(par.dynamic[k])} ± ${fmt((par.stderr || {})[k])}` : "–"]),
      ...staticRows(par),
      ["fit P / Q", par ? `${fmt(par.fit.fd_p)} / ${fmt(par.fit.fd_q)}` : "–"],
      ["excitation", excitationText(par)],
      ["flags", par && par.flags.length ? par.flags.join(" ") : "none"],
      ["values from", lastOk ? utc(lastOk.period) : "–"],
      ["diagnosis", d ? el("span", { class: `verdict ${d.verdict}` }, d.verdict + (d.cause ? ` (${d.cause})` : "")) : "none yet"],
    ]);
    const s = config.settings;
    kv("#state", [
      ["period T", `${health.period_s} s`],
      ["next period", utc(health.next_period)],
      ["running", health.running_period ? utc(health.running_period) : "no"],
      ["window", `${s.window_s} s at ${s.frame_rate} frames/s, late allowance ${s.late_s} s`],
      ["diagnosis", s.diagnose_every ? `every ${s.diagnose_every} periods` : "off"],
      ["identifier", `${s.objective}, ${s.n_starts} starts (warm +${s.n_starts_warm}), low-pass ${s.lowpass_hz == null ? "adaptive" : s.lowpass_hz + " Hz"}`],
      // What the workers' identifier did on the newest window (its IdentifyConfig travels with the result): the
      // noisy-input and own-fluctuation estimators are the library's defaults, not service settings.
      ["estimator", par && par.config ? el("span", { id: "estimator" },
        `inputs ${par.config.input_smoother}, weighting ${par.config.input_weighting}, disturbance ${par.config.disturbance}` +
        (par.config.couple_channels ? " on P and Q − k·P" : "")) : "–"],
      ["workers", `${s.workers} (${s.executor}), ${health.workers_replaced} replaced`],
      ["frames", `${health.frames_received} received, ${health.frames_dropped} dropped`],
    ]);
    drawHistory(history);
    drawPlayback(pb);
    $("#diagnoses tbody").replaceChildren(...diagnoses.map((e) => el("tr", {}, [
      utc(e.period), el("span", { class: `verdict ${e.verdict}` }, e.verdict), e.cause || (e.causes || []).join(" | ") || "–", e.channels.join(" ") || "–",
      e.fit_before ? `${fmt(e.fit_before.fd_p)} → ${fmt(e.fit_after && e.fit_after.fd_p)}` : "–",
      e.fit_before ? `${fmt(e.fit_before.fd_q)} → ${fmt(e.fit_after && e.fit_after.fd_q)}` : "–",
      e.message || "",
    ].map((v) => el("td", { class: "txt" }, v)))));
  }

  // --- routing and refresh -----------------------------------------------------------------------------
  function route() {
    const m = location.hash.match(/^#\/bus\/(.+)$/);
    return m ? decodeURIComponent(m[1]) : null;
  }

  async function refresh() {
    if (ui.busy) { ui.again = true; return; }  // a click during a refresh: run once more after it
    ui.busy = true;
    try {
      await (ui.bus === null ? refreshFleet() : refreshBus(ui.bus));
      showError(null);
      $("#updated").textContent = `updated ${new Date().toLocaleTimeString()}`;
      document.body.dataset.refreshes = String(+(document.body.dataset.refreshes || 0) + 1);
      // Time from navigation start to the first page drawn with data [ms] (read by the benchmark).
      if (!document.body.dataset.firstRenderMs) document.body.dataset.firstRenderMs = performance.now().toFixed(1);
    } catch (err) {
      showError(err);
    } finally {
      ui.busy = false;
    }
    if (ui.again) { ui.again = false; await refresh(); }
  }

  function schedule() {
    clearTimeout(ui.timer);
    const every = +$("#refresh").value;
    if (every > 0) ui.timer = setTimeout(async () => { await refresh(); schedule(); }, every * 1000);
  }

  function refreshNow() {
    refresh().then(schedule);
  }

  function navigate() {
    ui.bus = route();
    for (const c of Object.values(ui.charts)) c.destroy();
    if (ui.bus === null) renderFleet(); else renderBus(ui.bus);
    refreshNow();
  }

  window.addEventListener("hashchange", navigate);
  $("#refresh").addEventListener("change", schedule);
  navigate();
})();
