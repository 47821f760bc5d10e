/* scengen dashboard, section 7 (docs/dashboard.md, docs/evaluation.md): a system under
 * test. Its collision rate per hour with the Monte Carlo and the model interval beside the
 * R157 careful driver's, the failing runs, the SUT's peak r_dep against btn; one run's
 * speed, acceleration and r_dep beside the careful driver's is drawn in the scenario view
 * (view 4, #scenario-run), opened from a failing run or a point. Reads /evaluations and
 * /dashboard/api/evaluations/{id}; starts an evaluation with POST /evaluations. Plot <div>s
 * get data-rendered="1"; the note gets data-state="done" | "empty" | "error".
 */
"use strict";

(function () {
  const S = window.scengen;

  // peak r_dep of the SUT's drive: NaN (or "NaN") when the evaluation did not ask for risk
  function riskCell(x) {
    const v = typeof x === "string" ? Number(x) : x;
    return v === null || v === undefined || Number.isNaN(v) ? "not computed" : S.fmt(v);
  }
  const $ = (id) => document.getElementById(id);
  const VS_CAREFUL = "worse, same or better than UN R157's careful driver on the same " +
    "cut-in (worse: collides where it does not, or at a higher relative impact speed)";
  const WEIGHT = "the run's importance weight p/q in P(collision)";
  const SHARE = "the run's weight over the sum of the weights of all collided runs the " +
    "estimate counts (P is that sum over the number of draws it counts; pilot runs of a " +
    "cross-entropy campaign are left out)";
  const RISK_HINT = "not computed: start the evaluation with risk: true (--risk, or tick " +
    "'score the drive with TTR risk') to " +
    "compute Wagner's r_dep of the SUT's drive; it costs several times the simulation";
  const SUT = "#c62828";
  const CAREFUL = "#2e7d32";
  let poll = null;
  let carefulPoll = null;

  // rates and probabilities in one notation (before, 0.00131 [8.09e-4, 0.00213]: the ends
  // of one interval in two notations)
  function sci(x) {
    const v = typeof x === "string" ? Number(x) : x;
    return typeof v === "number" && isFinite(v) && v !== 0 ? v.toExponential(2) : S.fmt(x, 3);
  }

  function interval(ci) {
    if (!ci) return "–";
    return "[" + sci(ci[0]) + ", " + sci(ci[1]) + "]";
  }

  // how many draws were cut-ins the SUT drove: the weight roulette left some unrun (they
  // count through the weights of those run), the others (outside the physical bounds or
  // the region) count as no collision
  function countCell(f) {
    const pilot = f.pilot_runs ? "; the estimate counts the " + (f.runs - f.pilot_runs) +
      " draws after the " + f.pilot_runs + " pilot draws" : "";
    const skipped = f.skipped_runs ? f.skipped_runs + " over-sampled draws left unrun by " +
      "the weight roulette (the runs kept weigh for them); " : "";
    return f.collisions + " collisions in " + f.runs + " draws (" + f.sut_runs +
      " simulated cut-ins; " + skipped + "the rest fall outside the physical bounds or " +
      "the region and count as no collision" + pilot + ")";
  }

  // without any collision there is no interval, only the 95 % upper bound (for the rate
  // too: "0 [–, –]" read as "never collides")
  function mcCell(x) {
    return x.upper_bound !== null && x.upper_bound !== undefined
      ? "≤ " + sci(x.upper_bound) + " (95 % bound)" : interval(x.ci);
  }

  function figureRows(label, f) {
    if (!f) return [[label, "–", "–", "–", "–"]];
    const r = f.rate_per_hour || {};
    const p = f.p_collision || {};
    const rows = [[label + " · collisions per hour", sci(r.estimate), mcCell(r),
                   interval(r.model_ci), countCell(f)]];
    rows.push([label + " · P(collision) per cut-in", sci(p.estimate), mcCell(p),
               interval(p.model_ci), p.upper_bound !== null && p.upper_bound !== undefined
                 ? "no collision: ≤ " + sci(p.upper_bound) + " (95 %)"
                 : f.unreliable ||
                   "ESS " + S.fmt(f.ess, 3) + ", ×" + S.fmt(f.acceleration, 3) + " vs naive MC"]);
    // too few collisions or too small an ESS (the view's rule): the intervals greyed, the
    // speed-up replaced by the warning
    if (f.unreliable) {
      rows[0].cls = "unreliable";
      rows[1].cls = "unreliable flagged";
    }
    return rows;
  }

  function grid(head, rows) {
    return "<table><tr>" + head.map((h) => "<th>" + S.esc(h) + "</th>").join("") + "</tr>" +
      rows.map((r) => "<tr" + (r.cls ? " class=\"" + r.cls + "\"" : "") + ">" +
                 r.map((v, i) => (i === 0 ? "<th>" : "<td>") + S.esc(v) +
                                 (i === 0 ? "</th>" : "</td>")).join("") + "</tr>")
        .join("") + "</table>";
  }

  async function loadLists(selectId) {
    const [{ evaluations }, { suts }] = await Promise.all([S.api("/evaluations"),
                                                          S.api("/suts")]);
    const sel = $("eval-select");
    sel.innerHTML = "";
    for (const e of evaluations.slice().reverse()) {
      const o = document.createElement("option");
      o.value = e.id;
      o.textContent = e.sut + " · " + e.status + " · " + e.id;
      sel.appendChild(o);
    }
    if (selectId) sel.value = selectId;
    const sutSel = $("sut-select");
    if (!sutSel.options.length) {
      for (const s of suts) {
        const o = document.createElement("option");
        o.value = s.name;
        o.textContent = s.name;
        o.title = s.summary + (s.source ? " — " + s.source : "");
        sutSel.appendChild(o);
      }
      sutSel.value = suts.some((s) => s.name === "acc") ? "acc" : (suts[0] || {}).name;
    }
    return evaluations;
  }

  async function start(event) {
    event.preventDefault();
    const n = parseInt($("eval-n").value, 10);
    if (!(n >= 1)) {
      $("eval-n").classList.add("invalid");
      S.reportError("start an evaluation", new Error("n must be a whole number ≥ 1"));
      return;
    }
    try {
      const made = await S.api("/evaluations", {
        method: "POST", headers: { "Content-Type": "application/json" },
        body: JSON.stringify({ sut: $("sut-select").value, n: n,
                               model: $("model-select").value || "default",
                               risk: $("eval-risk").checked }),
      });
      await loadLists(made.id);
      await show(made.id);
    } catch (e) {
      S.reportError("start an evaluation (section 7)", e);
    }
  }

  async function show(id) {
    const note = $("sut-note");
    if (poll) { clearTimeout(poll); poll = null; }
    if (carefulPoll) { clearTimeout(carefulPoll); carefulPoll = null; }
    $("sut-careful").textContent = "";
    drawWarnings([]);
    if (!id) {
      note.textContent = "No evaluation yet: pick a system under test and press Evaluate " +
        "(or run 'scengen evaluate', POST /evaluations).";
      note.dataset.state = "empty";
      return;
    }
    let view;
    try {
      view = await S.api("/dashboard/api/evaluations/" + encodeURIComponent(id));
    } catch (e) {
      note.dataset.state = "error";
      S.reportError("the system under test (section 7)", e);
      return;
    }
    const ev = view.evaluation;
    if (ev.status === "queued" || ev.status === "running") {
      note.textContent = "Evaluation " + ev.id + " of " + ev.sut + " is " + ev.status + ": " +
        ev.runs_done + " of " + ev.runs_planned + " runs, " + ev.collisions_so_far +
        " collisions so far…";
      note.dataset.state = "running";
      poll = setTimeout(() => show(id), 1000);
      return;
    }
    if (ev.status !== "done") {
      note.textContent = "Evaluation " + ev.id + " is " + ev.status +
        (ev.error ? ": " + ev.error : "") + ".";
      note.dataset.state = "error";
      return;
    }
    const region = ev.constraints.length ? ev.constraints.join(" and ") : "all cut-ins of the model";
    note.textContent = "Evaluation " + ev.id + ": " + ev.sut + " driven through " +
      view.figures.sut_runs + " importance-sampled cut-ins of " + view.figures.runs +
      " draws (" + region + ", seed " + ev.seed +
      "); rates with the Monte Carlo interval and the model interval (the data's " +
      "uncertainty, from the bootstrap refits).";
    drawTable(view);
    drawFailures(view);
    await drawScatter(view);
    note.dataset.state = "done";
    // the first failing run is drawn in view 4 without moving the page there
    if (view.failures.length) await openRun(ev.id, view.failures[0].run, false);
    else {
      $("sut-run-info").textContent = "Evaluation " + ev.id + " of " + ev.sut +
        ": no run collided, so no failing run to drive again.";
      S.clearPlot($("sut-run-plot"), "No failing run to show.");
    }
  }

  // the SUT's rates and the careful driver's beside them; without a finished careful
  // evaluation on this model and region, how to get one (a button that starts it) or its
  // progress (polled until it is done)
  function drawTable(view) {
    const ev = view.evaluation;
    const rows = figureRows(ev.sut, view.figures);
    const box = $("sut-careful");
    const c = view.careful;
    if (carefulPoll) { clearTimeout(carefulPoll); carefulPoll = null; }
    box.textContent = "";
    if (c && c.figures) {
      rows.push(...figureRows("r157_cc (careful driver)", c.figures));
      box.dataset.state = "done";
    } else if (c) {
      rows.push(["r157_cc (careful driver)", "–", "–", "–", "evaluation " + c.id + " " +
                 c.status + ": " + c.runs_done + " of " + c.runs_planned + " runs…"]);
      box.textContent = "The careful driver's rate appears here when its evaluation " +
        c.id + " is done.";
      box.dataset.state = "running";
      carefulPoll = setTimeout(() => refreshCareful(ev.id), 2000);
    } else {
      rows.push(["r157_cc (careful driver)", "–", "–", "–",
                 "no evaluation of r157_cc on this model and region yet"]);
      const req = view.careful_request;
      box.append("The careful driver's rate needs its own evaluation on the same model, " +
                 "region, seed and runs: ");
      const btn = document.createElement("button");
      btn.id = "careful-button";
      btn.type = "button";
      btn.textContent = "Evaluate r157_cc here";
      btn.addEventListener("click", () => startCareful(ev.id, req, btn));
      box.append(btn, " (or POST /evaluations " + JSON.stringify(req) + ").");
      box.dataset.state = "none";
    }
    $("sut-table").innerHTML = grid(["", "estimate", "Monte Carlo 95 %", "model 95 %", ""],
                                    rows);
    drawWarnings([[ev.sut, view.figures], ["r157_cc", c && c.figures]]);
  }

  // every warning of the summaries (no collision, few collisions, a small ESS, stopped at
  // max_runs, a ce campaign without its final stage), one line each: the flag in the
  // table covers only the first three
  function drawWarnings(pairs) {
    const list = $("sut-warnings");
    list.textContent = "";
    for (const [who, f] of pairs) {
      for (const text of (f && f.warnings) || []) {
        const li = document.createElement("li");
        li.textContent = who + ": " + text;
        list.appendChild(li);
      }
    }
    list.hidden = !list.childElementCount;
  }

  async function refreshCareful(id) {
    carefulPoll = null;
    if ($("eval-select").value !== id) return;  // the user went on to another evaluation
    try {
      drawTable(await S.api("/dashboard/api/evaluations/" + encodeURIComponent(id)));
    } catch (e) {
      S.reportError("the careful driver's evaluation (section 7)", e);
    }
  }

  async function startCareful(id, req, btn) {
    btn.disabled = true;
    try {
      await S.api("/evaluations", {
        method: "POST", headers: { "Content-Type": "application/json" },
        body: JSON.stringify(req),
      });
      await loadLists(id);
      await refreshCareful(id);
    } catch (e) {
      btn.disabled = false;
      S.reportError("start the careful driver's evaluation (section 7)", e);
    }
  }

  function drawFailures(view) {
    const box = $("sut-failures");
    if (!view.failures.length) {
      box.innerHTML = "<p class=\"note\">No run collided.</p>";
      return;
    }
    const head = ["run", "share of P", "weight", "impact speed (relative) [m/s]", "peak r_dep",
                  "vs careful", "cutter v0 [m/s]", "dv [m/s]", "gap [m]"];
    const tips = {
      "share of P": SHARE,
      "weight": WEIGHT,
      "impact speed (relative) [m/s]": "the ego's speed minus the cutter's at contact",
      "peak r_dep": "the highest Wagner r_dep of the SUT's drive",
      "vs careful": VS_CAREFUL,
    };
    // the share is the server's (view.failures[i].share); a pilot run has none
    const share = (r) => r.counted === false ? "pilot (not counted)"
      : r.share === null || r.share === undefined ? "–" : S.fmt(100 * r.share) + " %";
    const body = view.failures.map((r) => "<tr data-run=\"" + r.run + "\"><td><a href=\"#\">" +
      r.run + "</a></td><td>" + S.esc(share(r)) + "</td><td>" + S.esc(S.fmt(r.weight)) +
      "</td><td>" + S.esc(S.fmt(r.impact_speed)) + "</td><td>" +
      S.esc(riskCell(r.r_dep_peak)) + "</td><td>" + S.esc(r.vs_careful || "–") + "</td><td>" +
      S.esc(S.fmt(r.p_v0)) + "</td><td>" + S.esc(S.fmt(r.dv)) + "</td><td>" +
      S.esc(S.fmt(r.gap)) + "</td></tr>").join("");
    const counted = view.failures.filter((r) => r.counted !== false).length;
    const shown = (view.failures.length < view.failures_total
      ? "the " + counted + " that carry most of P, largest weight first"
      : "largest weight first (those that carry most of P)") +
      (view.failures_pilot ? "; " + view.failures_pilot + " of them " +
       (view.failures_pilot === 1 ? "is a pilot run" : "are pilot runs") + " of the " +
       "cross-entropy campaign, not counted in P, listed after the others" : "");
    box.innerHTML = "<p class=\"note\">" + view.failures_total + " failing runs, " + shown +
      " (click one to drive it again beside the careful driver in " +
      "view 4 · Scenario):</p><table><tr>" +
      head.map((h) => "<th" + (tips[h] ? " title=\"" + S.esc(tips[h]) + "\"" : "") + ">" +
               S.esc(h) + "</th>").join("") + "</tr>" + body + "</table>" +
      "<p class=\"note\" id=\"sut-failures-legend\">share of P: " + S.esc(SHARE) +
      ". weight: " + S.esc(WEIGHT) + ". vs careful: " + S.esc(VS_CAREFUL) + "." +
      (view.scatter.note || view.failures.some((r) =>
        riskCell(r.r_dep_peak) === "not computed") ? " peak r_dep " + S.esc(RISK_HINT) + "." : "") + "</p>";
    box.querySelectorAll("tr[data-run]").forEach((tr) => tr.addEventListener("click", (e) => {
      e.preventDefault();
      openRun(view.evaluation.id, parseInt(tr.dataset.run, 10), true);
    }));
  }

  async function drawScatter(view) {
    const s = view.scatter;
    const div = $("sut-scatter");
    if (!s.run.length) {
      S.clearPlot(div, "No simulated run to plot.");
      return;
    }
    const pick = (hit) => s.run.map((_, i) => i).filter((i) => s.collided[i] === hit);
    // without r_dep (the runner did not compute it) the impact speed stands in, said so
    const y = s.note ? s.impact_speed : s.r_dep_peak;
    const yName = s.note ? "impact speed, relative [m/s]" : "peak r_dep of the SUT's drive";
    const trace = (idx, name, color) => ({
      type: "scatter", mode: "markers", name: name,
      x: idx.map((i) => s.btn[i]), y: idx.map((i) => y[i]),
      customdata: idx.map((i) => s.run[i]),
      marker: { size: 7, color: color, opacity: 0.75, line: { width: 0.5, color: "#333" } },
      hovertemplate: "run %{customdata}<br>btn %{x:.3f}<br>" + yName +
        " %{y:.3f}<extra></extra>",
    });
    await S.draw(div, [trace(pick(false), "no collision", "#8a94a3"),
                       trace(pick(true), "collided", SUT)], {
      // the note on a line of its own: one line of both overflowed the plot at 1400 px
      title: { text: s.note ? "Impact speed against btn<br>(" + S.esc(s.note) + ")"
                            : "SUT's peak r_dep against btn", font: { size: 11 } },
      margin: { l: 48, r: 12, t: s.note ? 46 : 30, b: 42 },
      xaxis: { title: { text: "btn (braking needed ÷ available)" } },
      // impact speed and r_dep are never negative (without a collision the axis ran
      // from -1 to 1 around the zeros)
      yaxis: { title: { text: yName }, rangemode: "nonnegative" },
      legend: { orientation: "h", x: 0, y: -0.25, font: { size: 10 } },
    }, view.evaluation.id);
    div.on("plotly_click", (ev) => {
      const p = ev.points && ev.points[0];
      if (p) openRun(view.evaluation.id, p.customdata, true);
    });
  }

  // one run driven again by the SUT and by the careful driver, drawn in the scenario view
  // (view 4); `scroll`: move the page there (a click), not when the section first loads
  async function openRun(id, run, scroll) {
    const div = $("sut-run-plot");
    let view;
    try {
      view = await S.api("/dashboard/api/evaluations/" + encodeURIComponent(id) + "/runs/" + run);
    } catch (e) {
      S.reportError("run " + run + " (section 7)", e);
      return;
    }
    // the user went on to another evaluation while this run was driven again
    if ($("eval-select").value !== id) return;
    const d = view.drivers;
    // the series end at the drive's end: trailing nulls (the risk's time grid runs on
    // past a collision) only stretched the time axis
    const line = (drv, key, color, axis, dash, label) => {
      const x = (key === "r_dep" ? drv.t_risk : drv.t) || [];
      const y = drv[key] || [];
      let n = Math.min(x.length, y.length);
      while (n > 0 && (y[n - 1] === null || y[n - 1] === undefined)) n--;
      return { type: "scatter", mode: "lines", name: label, x: x.slice(0, n),
               y: y.slice(0, n), xaxis: "x", yaxis: axis,
               line: { color: color, width: 2, dash: dash } };
    };
    const traces = [];
    for (const [drv, color, who] of [[d.sut, SUT, d.sut.name], [d.careful, CAREFUL, "careful"]]) {
      traces.push(line(drv, "v", color, "y", null, who + " speed"));
      traces.push(line(drv, "a", color, "y2", "dot", who + " accel"));
      if (drv.r_dep) traces.push(line(drv, "r_dep", color, "y3", "dash", who + " r_dep"));
    }
    // the impact speed is the relative speed at contact, not the ego's speed plotted below
    const outcome = (drv) => drv.collided ? "collides at a relative speed of " +
      S.fmt(drv.impact_speed) + " m/s"
      : "no collision (smallest gap " + S.fmt(drv.min_gap) + " m)";
    const info = $("sut-run-info");
    info.textContent = "Run " + run + ": " + d.sut.name + " " + outcome(d.sut) +
      "; careful driver " + outcome(d.careful) + (d.sut.r_dep ? "" :
        " (r_dep of the drive not computed by this version of the simulator)") +
      " (evaluation " + id + "). ";
    const back = document.createElement("a");
    back.href = "#view-sut";
    back.textContent = "Back to its failing runs (section 7)";
    info.append(back);
    await S.draw(div, traces, {
      title: { text: "Run " + run + ": speed, acceleration and r_dep, SUT beside the careful " +
               "driver", font: { size: 12 } },
      grid: { rows: 3, columns: 1, pattern: "coupled" },
      xaxis: { title: { text: "time [s]" } },
      yaxis: { title: { text: "speed [m/s]" } },
      yaxis2: { title: { text: "accel [m/s²]" } },
      yaxis3: { title: { text: "r_dep" }, range: [0, 1.05] },
      legend: { orientation: "h", y: -0.15, x: 0, font: { size: 10 } },
      height: 520,
    }, id + "#" + run);
    if (scroll) {
      // to the panel's top, just below the sticky header (its height varies with the width)
      const top = $("scenario-run").getBoundingClientRect().top + window.scrollY;
      window.scrollTo({ top: top - document.querySelector("header").offsetHeight - 8 });
    }
  }

  async function init() {
    $("eval-form").addEventListener("submit", start);
    $("eval-select").addEventListener("change", (e) => show(e.target.value));
    try {
      const evals = await loadLists();
      const done = evals.filter((e) => e.status === "done" && e.sut !== "r157_cc");
      const pick = (done[done.length - 1] || evals[evals.length - 1] || {}).id;
      if (pick) $("eval-select").value = pick;
      await show(pick);
    } catch (e) {
      $("sut-note").dataset.state = "error";
      S.reportError("the system under test (section 7)", e);
    }
  }

  init();
})();
