/* scengen dashboard, sections 5 and 6 (docs/dashboard.md): how often a region occurs
 * (P(A) with its Monte Carlo and model intervals, cut-ins per hour / per 10^6 km) and two
 * fitted models side by side. Uses the helpers dashboard.js shares as window.scengen and
 * reads the header's model, catalogue and constraint controls. Each plot <div> gets
 * data-rendered="1" after drawing (tests wait on it); each section's note gets
 * data-state="done" | "error" when its figures are in.
 */
"use strict";

(function () {
  const S = window.scengen;
  const $ = (id) => document.getElementById(id);
  const BLUE = "#1f5fbf";
  const ORANGE = "#e07b00";
  const GREEN = "#2e7d32";
  const UNITS = [["per_hour", "per hour of driving"], ["per_1e6_km", "per 10⁶ km driven"]];

  function constraintText() {
    return ($("constraint-input").value || "").trim() || "ttc<3";
  }

  // what the region's cut-ins are, in words
  function regionWords(constraints) {
    const unpreventable = constraints.some((c) => /^\s*btn\s*>=?\s*(1(\.0*)?|[2-9]|\d{2,})/.test(c));
    const collide = constraints.some((c) => /^\s*r157_collision\s*>/.test(c));
    const what = unpreventable ? "unpreventable cut-ins (the careful driver cannot avoid them)"
      : collide ? "cut-ins in which the careful driver collides" : "cut-ins";
    return what + " with " + (constraints.join(" and ") || "no constraint");
  }

  // zero: a lower end below what subset-is resolves (P(A) < 1e-14; its rate is near 0)
  function interval(ci, resolved, zero) {
    if (!ci) return "–";
    const low = resolved === false ? "lower end not resolved"
      : ci[0] === 0 && zero ? zero : S.fmt(ci[0], 3);
    return "[" + low + ", " + S.fmt(ci[1], 3) + "]";
  }

  function resolvedOf(p) {
    return p && p.model_interval ? p.model_interval.lower_resolved : null;
  }

  function figureRows(p, rates) {
    const res = resolvedOf(p);
    const rows = [["P(A) (share of physical cut-ins)", S.fmt(p.estimate, 3),
                   interval(p.mc_ci), interval(p.model_ci, res, "< 1e-14")]];
    for (const [unit, words] of UNITS) {
      const r = rates && rates[unit];
      if (r) {
        rows.push(["rate " + words, S.fmt(r.estimate, 3), interval(r.mc_ci),
                   interval(r.model_ci, r.model_lower_resolved, "≈ 0")]);
      }
    }
    return rows;
  }

  function grid(head, rows) {
    return "<table><tr>" + head.map((h) => "<th>" + S.esc(h) + "</th>").join("") + "</tr>" +
      rows.map((r) => "<tr>" + r.map((v, i) => (i === 0 ? "<th>" : "<td>") + S.esc(v) +
                                       (i === 0 ? "</th>" : "</td>")).join("") + "</tr>")
        .join("") + "</table>";
  }

  function exposureWords(e) {
    if (!e) return "no exposure: rates need the hours or km in which the data were recorded";
    const parts = [];
    if (e.hours) parts.push(S.fmt(e.hours, 4) + " h");
    if (e.km) parts.push(S.fmt(e.km, 4) + " km");
    return e.n_events + " cut-ins in " + parts.join(" and ") + " (" + e.source + ")";
  }

  // ---------------------------------------------------------------- section 5
  let ratesVersion = 0;
  // the catalogue dashboard.js shows (undefined until it says: the picker's value)
  let shown;

  async function loadRates() {
    const note = $("rates-note");
    if (!$("model-select").value) return;
    const version = ++ratesVersion;
    note.dataset.state = "loading";
    try {
      // a selected catalogue brings its own region and model (before, the region was the
      // typed constraint: a ttc<2 catalogue was shown under "ttc<3")
      const catalogue = shown === undefined ? $("catalogue-select").value : shown;
      const cat = catalogue ? await S.api("/catalogues/" + encodeURIComponent(catalogue))
        : null;
      if (version !== ratesVersion) return;
      const model = cat ? cat.model : $("model-select").value;
      const text = cat ? cat.constraints.join("; ") : constraintText();
      note.textContent = "Estimating P(" + (text || "no constraint") + ") and its model " +
        "interval under " + model + " (one extra sampling run of the bootstrap refits)…";
      const q = "?constraints=" + encodeURIComponent(text);
      const view = await S.api("/dashboard/api/models/" + encodeURIComponent(model) +
                               "/rates" + q);
      if (version !== ratesVersion) return;
      const p = view.p_region;
      const mi = p.model_interval;
      note.textContent = "How often real drivers produce " + regionWords(view.constraints) +
        ", by model " + view.model + ". Monte Carlo: the estimator's own 95 % interval. " +
        "Model: " + (mi ? "the 95 % interval over " + mi.n_boot + " bootstrap refits of " +
        "the model to its data (what the few recorded events leave open; usually much " +
        "wider)" : p.model_interval_error ? p.model_interval_error
          : "none (the model has no bootstrap refits)") +
        ". Exposure: " + exposureWords(view.exposure) + "." +
        (cat ? " The region is catalogue " + cat.id + "'s; with no catalogue selected it " +
               "is the constraint typed above." : "");
      let html = "<h3>Region " + S.esc(view.constraints.join(" and ")) + " under model " +
        S.esc(view.model) + "</h3>" +
        grid(["", "estimate", "Monte Carlo 95 %", "model 95 %"], figureRows(p, view.rates));
      if (mi && mi.note) html += "<p class=\"note warn\">" + S.esc(mi.note) + "</p>";
      if (cat && cat.rates) {
        const w = cat.rates.from_weights || {};
        html += "<h3>Catalogue " + S.esc(cat.id) + " (" + S.esc(cat.constraints.join(" and ")) +
          ", n = " + cat.n + ")</h3>" +
          grid(["", "estimate", "Monte Carlo 95 %", "model 95 %"],
               figureRows(Object.assign({}, cat.p_region, { estimate: cat.p_region.estimate }),
                          cat.rates)) +
          "<p class=\"note\">Its " + cat.scenarios_stored + " exposure weights sum to " +
          S.fmt(w.sum_weights, 4) + " = P(A); times the rate of all cut-ins: " +
          S.fmt(w.per_hour, 4) + " per hour" +
          (w.per_1e6_km !== undefined ? ", " + S.fmt(w.per_1e6_km, 4) + " per 10⁶ km" : "") +
          ".</p>";
      } else if (cat) {
        html += "<p class=\"note\">Catalogue " + S.esc(cat.id) + ": no rates (its model has " +
          "no exposure, or the catalogue predates them).</p>";
      }
      $("rates-table").innerHTML = html;
      await drawReplicates(view);
      await drawRateBars(view, cat);
      await loadTails(view.model);
      note.dataset.state = "done";
    } catch (e) {
      if (version !== ratesVersion) return;
      note.dataset.state = "error";
      note.textContent = "No rates: " + e.message;
      S.reportError("how often (section 5)", e);
    }
  }

  async function drawReplicates(view) {
    const div = $("rates-replicates");
    const p = view.p_region;
    const reps = ((p.model_interval || {}).replicates || []).filter((v) => v > 0);
    if (!reps.length) {
      S.clearPlot(div, p.model_interval_error
        ? "No refits to draw: " + p.model_interval_error + "."
        : p.model_interval ? "No refit puts any mass in this region."
          : "The model has no bootstrap refits (fit with n_bootstrap > 0).");
      return;
    }
    const logs = reps.map((v) => Math.log10(v));
    const shapes = [];
    const band = (ci, color, y0, y1) => {
      if (!ci || !(ci[0] > 0) || !(ci[1] > 0)) return;
      shapes.push({ type: "rect", xref: "x", yref: "paper", x0: Math.log10(ci[0]),
                    x1: Math.log10(ci[1]), y0: y0, y1: y1, fillcolor: color, opacity: 0.25,
                    line: { width: 0 }, layer: "below" });
    };
    band(p.model_ci, ORANGE, 0, 1);
    band(p.mc_ci, GREEN, 0.9, 1);
    if (p.estimate > 0) {
      shapes.push({ type: "line", xref: "x", yref: "paper", x0: Math.log10(p.estimate),
                    x1: Math.log10(p.estimate), y0: 0, y1: 1,
                    line: { color: "#000", width: 2 } });
    }
    await S.draw(div, [{ type: "histogram", x: logs, nbinsx: 30, name: "refits",
                         marker: { color: BLUE, opacity: 0.7 },
                         hovertemplate: "log10 P(A) %{x}: %{y} refits<extra></extra>" }], {
      title: { text: "P(A) under each bootstrap refit (orange: model 95 %, green: Monte " +
               "Carlo 95 %, black: estimate)", font: { size: 12 } },
      xaxis: { title: { text: "log10 P(A)" } },
      yaxis: { title: { text: "refits" } }, shapes: shapes, showlegend: false,
    }, view.model);
  }

  async function drawRateBars(view, cat) {
    const div = $("rates-bars");
    const items = [];
    if (view.rates) items.push(["this region", view.p_region, view.rates]);
    if (cat && cat.rates) items.push(["catalogue " + cat.id, cat.p_region, cat.rates]);
    if (!items.length) {
      S.clearPlot(div, "No rates: the model carries no exposure (hours or km driven).");
      return;
    }
    // one row per (item, unit); the two intervals just above and below it
    const rows = [];
    for (const [label, , rates] of items) {
      for (const [unit, words] of UNITS) {
        if (rates[unit]) rows.push([label + " · " + words, rates[unit]]);
      }
    }
    const traces = [];
    for (const [kind, color, key, dy] of [["Monte Carlo 95 %", GREEN, "mc_ci", 0.12],
                                          ["model 95 %", ORANGE, "model_ci", -0.12]]) {
      const xs = [], lo = [], hi = [], ys = [];
      rows.forEach(([, r], i) => {
        if (!r[key] || !(r.estimate > 0)) return;
        xs.push(r.estimate);
        lo.push(r.estimate - Math.max(r[key][0], r.estimate * 1e-6));
        hi.push(r[key][1] - r.estimate);
        ys.push(i + dy);
      });
      traces.push({ type: "scatter", mode: "markers", name: kind, x: xs, y: ys,
                    marker: { color: color, size: 9 },
                    hovertemplate: "%{x:.3g}<extra>" + kind + "</extra>",
                    error_x: { type: "data", symmetric: false, array: hi, arrayminus: lo,
                               color: color, thickness: 2, width: 6 } });
    }
    await S.draw(div, traces, {
      title: { text: "Rate of " + regionWords(view.constraints), font: { size: 12 } },
      xaxis: { type: "log", title: { text: "cut-ins per unit of driving (log scale)" } },
      yaxis: { tickvals: rows.map((_, i) => i), ticktext: rows.map(([l]) => l),
               range: [-0.6, rows.length - 0.4], automargin: true, zeroline: false },
      legend: { orientation: "h", x: 0, y: -0.3, font: { size: 10 } },
      margin: { l: 10, r: 12, t: 36, b: 80 },
    }, view.model);
  }

  // tail calibration of the model's fit report (k-fold held out)
  async function loadTails(model) {
    const div = $("tails-plot");
    const detail = await S.api("/models/" + encodeURIComponent(model));
    const tc = (detail.fit_report || {}).tail_calibration;
    const rows = (tc && tc.rows) || [];
    if (!rows.length) {
      $("tails-note").textContent = "This model's fit report has no tail calibration.";
      $("tails-table").innerHTML = "";
      S.clearPlot(div, "No tail calibration in the fit report.");
      return;
    }
    $("tails-note").textContent = "For thresholds at the data's 2, 5, 10 and 25 % quantiles " +
      "of TTC, THW and gap: the probability of falling below each under models fitted " +
      "without a fold, against the share of that fold's held-out cut-ins that did (pooled " +
      "over the folds, exact 95 % interval). Below the data's smallest values (TTC < " +
      S.fmt(Math.min(...rows.filter((r) => r.quantity === "ttc").map((r) => r.threshold)), 3) +
      " s) there is nothing to check against: P(A) there is the model's extrapolation.";
    $("tails-table").innerHTML = grid(["quantity < threshold", "model", "held out [95 %]", ""],
      rows.map((r) => [r.quantity + " < " + S.fmt(r.threshold, 3), S.fmt(r.model_p, 3),
                       S.fmt(r.heldout_share, 3) + " [" + S.fmt(r.heldout_ci95[0], 2) + ", " +
                       S.fmt(r.heldout_ci95[1], 2) + "]", r.inside_ci ? "" : "outside"]));
    const colors = { ttc: GREEN, thw: ORANGE, gap: BLUE };
    const traces = ["ttc", "thw", "gap"].map((q) => {
      const rs = rows.filter((r) => r.quantity === q);
      return { type: "scatter", mode: "markers", name: q, x: rs.map((r) => r.model_p),
               y: rs.map((r) => r.heldout_share), marker: { color: colors[q], size: 8 },
               error_y: { type: "data", symmetric: false,
                          array: rs.map((r) => r.heldout_ci95[1] - r.heldout_share),
                          arrayminus: rs.map((r) => r.heldout_share - r.heldout_ci95[0]),
                          color: colors[q] } };
    });
    const top = Math.max(...rows.map((r) => Math.max(r.model_p, r.heldout_ci95[1]))) * 1.1;
    traces.push({ type: "scatter", mode: "lines", name: "equal", x: [0, top], y: [0, top],
                  line: { color: "#999", dash: "dot", width: 1 }, hoverinfo: "skip" });
    await S.draw(div, traces, {
      title: { text: "Held-out share against the model's probability", font: { size: 12 } },
      xaxis: { title: { text: "model P(q < threshold)" }, range: [0, top] },
      yaxis: { title: { text: "held-out share" }, range: [0, top] },
      legend: { orientation: "h", x: 0, y: -0.25, font: { size: 10 } },
      margin: { l: 48, r: 12, t: 30, b: 80 },
    }, model);
  }

  // ---------------------------------------------------------------- section 6
  function fillModels(models) {
    const def = models.find((m) => m["default"]) || models[0];
    const other = models.find((m) => !m["default"]) || def;
    for (const [id, pick] of [["compare-a", def], ["compare-b", other]]) {
      const select = $(id);
      select.innerHTML = "";
      for (const m of models) {
        const opt = document.createElement("option");
        opt.value = m.id;
        opt.textContent = m.id + (m["default"] ? " (default)" : "") + " · " + m.dataset;
        select.appendChild(opt);
      }
      if (pick) select.value = pick.id;
    }
    return models.length >= 2;
  }

  function steps(hist, name, color, dash) {
    return { type: "scatter", mode: "lines", name: name, x: S.centres(hist.edges),
             y: hist.density, line: { color: color, width: dash ? 1.5 : 2.5, dash: dash,
                                      shape: "hvh" },
             hovertemplate: "%{x:.3g}: %{y:.3g}<extra>" + name + "</extra>" };
  }

  async function loadCompare() {
    const a = $("compare-a").value;
    const b = $("compare-b").value;
    const note = $("compare-note");
    if (!a || !b) return;
    const text = constraintText();
    $("compare-button").disabled = true;
    $("compare-status").textContent = "sampling both models…";
    note.dataset.state = "loading";
    try {
      const view = await S.api("/models/compare?a=" + encodeURIComponent(a) + "&b=" +
                               encodeURIComponent(b) + "&constraints=" +
                               encodeURIComponent(text) + "&n=400");
      const [ma, mb] = view.models;
      note.textContent = "Model A (" + ma.id + ", fitted on " + ma.dataset + ") against model B (" +
        mb.id + ", fitted on " + mb.dataset + "): each parameter's distribution among " +
        "physical cut-ins (dotted) and inside " + view.constraints.join(" and ") +
        " (solid, " + view.n + " samples each), and how often the region occurs under each.";
      const rows = [];
      for (const [tag, m] of [["A", ma], ["B", mb]]) {
        for (const r of figureRows(m.p_region, m.rates)) rows.push([tag + " · " + r[0], r[1], r[2], r[3]]);
      }
      $("compare-table").innerHTML = grid(["", "estimate", "Monte Carlo 95 %", "model 95 %"], rows) +
        "<p class=\"note\">" + (JSON.stringify(ma.exposure) === JSON.stringify(mb.exposure)
          ? "Exposure of A and B: " + S.esc(exposureWords(ma.exposure))
          : "Exposure of A: " + S.esc(exposureWords(ma.exposure)) + ". Of B: " +
            S.esc(exposureWords(mb.exposure))) + ".</p>";
      $("compare-legend").innerHTML =
        "<span class=\"swatch\" style=\"background:" + BLUE + "\"></span>A " + S.esc(ma.id) +
        " <span class=\"swatch\" style=\"background:" + ORANGE + "\"></span>B " + S.esc(mb.id) +
        " · dotted: all physical cut-ins · solid: inside the region";
      const box = $("compare-grid");
      for (const p of view.parameters) {
        let div = document.getElementById("compare-" + p.name);
        if (!div) {
          div = document.createElement("div");
          div.id = "compare-" + p.name;
          div.className = "plot";
          box.appendChild(div);
        }
        const [ha, hb] = p.models;
        await S.draw(div, [steps(ha.unconstrained, "A all", BLUE, "dot"),
                           steps(ha.constrained, "A region", BLUE, null),
                           steps(hb.unconstrained, "B all", ORANGE, "dot"),
                           steps(hb.constrained, "B region", ORANGE, null)], {
          title: { text: p.name, font: { size: 12 } },
          xaxis: { title: { text: p.label } }, yaxis: { title: { text: "density" } },
          showlegend: false,
        }, ma.id + " vs " + mb.id);
      }
      note.dataset.state = "done";
      $("compare-status").textContent = "";
    } catch (e) {
      note.dataset.state = "error";
      $("compare-status").textContent = "";
      S.reportError("two models side by side (section 6)", e);
    } finally {
      $("compare-button").disabled = false;
    }
  }

  async function init() {
    let models = [];
    try {
      models = (await S.api("/models")).models;
    } catch (e) {
      S.reportError("models for sections 5 and 6", e);
      return;
    }
    const two = fillModels(models);
    $("compare-form").addEventListener("submit", loadCompare);
    $("model-select").addEventListener("change", loadRates);
    // every change of the shown catalogue (picker, Draw, Back), not only the picker's
    window.addEventListener("scengen:catalogue", (ev) => {
      shown = ev.detail;
      loadRates();
    });
    $("constraint-input").addEventListener("change", loadRates);
    // the header's selections are set by dashboard.js once its lists are in
    const start = Date.now();
    while (!$("model-select").value && Date.now() - start < 30000) {
      await new Promise((r) => setTimeout(r, 100));
    }
    await loadRates();
    if (two) await loadCompare();
    else {
      $("compare-note").textContent = "Only one fitted model so far: fit another (POST " +
        "/models on an uploaded dataset, e.g. a highD recording) to compare two datasets.";
      $("compare-note").dataset.state = "done";
    }
  }

  init();
})();
