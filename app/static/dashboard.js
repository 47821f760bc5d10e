/* scengen dashboard: plots of the JSON views under /dashboard/api (docs/dashboard.md).
 *
 * Every number plotted here was aggregated on the server (histograms binned, scatter
 * thinned), so the page stays fast for large catalogues. Each plot <div> gets
 * data-rendered="1" and an increasing data-version after every drawing, and data-source
 * naming what it shows (tests wait on these).
 */
"use strict";

(function () {
  const $ = (id) => document.getElementById(id);
  const PARAMS = ["p_y1", "p_t", "p_a1", "p_a2", "p_a3", "p_v0", "dv", "gap"];
  const COLORS = {
    data: "#1f5fbf", model: "#e07b00", unconstrained: "#8a94a3", constrained: "#c62828",
    r_dep: "#c62828", r_ind: "#1f5fbf", ego: "#1f5fbf", cutter: "#c62828",
    ttc: "#00838f", wttc: "#6a1b9a", thw: "#e07b00", r157: "#2e7d32",
  };
  const CONFIG = { displaylogo: false, responsive: true,
                   modeBarButtonsToRemove: ["lasso2d", "select2d"] };
  const BASE_LAYOUT = {
    margin: { l: 48, r: 12, t: 30, b: 42 },
    font: { size: 11 },
    paper_bgcolor: "#fff",
    plot_bgcolor: "#fff",
    legend: { orientation: "h", y: 1.14, x: 0, font: { size: 10 } },
  };

  let initial = {};
  try { initial = JSON.parse(document.body.dataset.initial || "{}"); } catch (e) { initial = {}; }

  const state = {
    datasets: [], models: [], catalogues: [],
    dataset: null, model: null, catalogue: null,
    cornerParams: null, fit: null,
    scenario: null, step: 0, timer: null, poll: null,
  };

  // ------------------------------------------------------------------ API and errors
  class ApiError extends Error {
    constructor(status, message, field) {
      super(message);
      this.status = status;
      this.field = field || null;
    }
  }

  // With SCENGEN_API_KEY set the service wants the key on writes and on its costly reads
  // (shift, rates, fit): the header's "API key" field keeps it for this tab only
  // (sessionStorage) and every request below sends it as X-API-Key.
  const KEY_STORE = "scengen-api-key";

  function apiKey() {
    try { return sessionStorage.getItem(KEY_STORE) || ""; } catch (e) { return ""; }
  }

  function keyField() {
    const input = $("api-key-input");
    if (!input) return;
    input.value = apiKey();
    input.addEventListener("change", () => {
      try { sessionStorage.setItem(KEY_STORE, input.value.trim()); } catch (e) { /* none */ }
      window.location.reload();  // every view asks again, with the key
    });
  }

  function keyRefused() {
    const form = $("key-form");
    if (form) form.dataset.needed = "1";
    return apiKey()
      ? "the service refused the API key entered in the header's \"API key\" field; " +
        "enter its key (SCENGEN_API_KEY) there"
      : "this service needs its API key (SCENGEN_API_KEY): enter it in the header's " +
        "\"API key\" field";
  }

  async function api(path, options) {
    const opts = Object.assign({}, options || {});
    const key = apiKey();
    if (key) {
      const headers = new Headers(opts.headers || {});
      headers.set("X-API-Key", key);
      opts.headers = headers;
    }
    let response;
    try {
      response = await fetch(path, opts);
    } catch (e) {
      throw new ApiError(0, "the service did not answer (" + e.message + ")");
    }
    let body = null;
    try { body = await response.json(); } catch (e) { body = null; }
    if (response.status === 401) {
      throw new ApiError(401, keyRefused(), "header.x-api-key");
    }
    if (!response.ok) {
      const err = body && body.error ? body.error : {};
      throw new ApiError(response.status, err.message || response.statusText, err.field);
    }
    return body;
  }

  // requests started before they are needed (the catalogue's views while the lists load)
  const early = new Map();

  function prefetch(path) {
    const promise = api(path);
    promise.catch(() => null);  // a failure is reported when the view asks for it
    early.set(path, promise);
  }

  // Export links: a plain <a href download> cannot send X-API-Key, so with the key set the
  // export answered 401. A plain click on a link marked data-export (its value: the file
  // name to use if the server names none) fetches the file with the key, as api() does,
  // and saves the body under the server's name (Content-Disposition) through a temporary
  // object URL; a refusal is said in #error. Without a key the same fetch runs keyless, so
  // a service without SCENGEN_API_KEY downloads as before. The href stays for "copy link".
  function dispositionName(header, fallback) {
    if (!header) return fallback;
    let m = /filename\*\s*=\s*UTF-8''([^;]+)/i.exec(header);
    if (m) {
      try { return decodeURIComponent(m[1].trim()); } catch (e) { /* the plain name below */ }
    }
    m = /filename\s*=\s*"([^"]*)"/i.exec(header) || /filename\s*=\s*([^;]+)/i.exec(header);
    return m && m[1].trim() ? m[1].trim() : fallback;
  }

  async function download(path, fallback) {
    const headers = new Headers();
    const key = apiKey();
    if (key) headers.set("X-API-Key", key);
    let response;
    try {
      response = await fetch(path, { headers });
    } catch (e) {
      throw new ApiError(0, "the service did not answer (" + e.message + ")");
    }
    if (response.status === 401) throw new ApiError(401, keyRefused(), "header.x-api-key");
    if (!response.ok) {
      let body = null;
      try { body = await response.json(); } catch (e) { body = null; }
      const err = body && body.error ? body.error : {};
      throw new ApiError(response.status, err.message || response.statusText, err.field);
    }
    const blob = await response.blob();
    const url = URL.createObjectURL(blob);
    const save = document.createElement("a");
    save.href = url;
    save.download = dispositionName(response.headers.get("Content-Disposition"), fallback);
    save.hidden = true;
    document.body.appendChild(save);
    save.click();
    save.remove();
    setTimeout(() => URL.revokeObjectURL(url), 60_000);
  }

  function exportLinks() {
    document.addEventListener("click", (event) => {
      const link = event.target instanceof Element ? event.target.closest("a[data-export]")
                                                   : null;
      if (!link || event.button !== 0 || event.ctrlKey || event.metaKey || event.shiftKey ||
          event.altKey) return;
      event.preventDefault();
      if (link.getAttribute("aria-busy") === "true") return;  // one download at a time
      link.setAttribute("aria-busy", "true");
      download(link.getAttribute("href"), link.dataset.export)
        .catch((e) => reportError("export " + link.dataset.export, e))
        .finally(() => link.removeAttribute("aria-busy"));
    });
  }

  function prefetched(path) {
    const promise = early.get(path);
    early.delete(path);
    return promise || api(path);
  }

  function showError(message) {
    // one line per distinct message until the next clearError
    const el = $("error");
    const lines = Array.from(el.querySelectorAll("div")).map((d) => d.textContent);
    if (!lines.includes(message)) {
      const line = document.createElement("div");
      line.textContent = message;
      el.appendChild(line);
    }
    el.hidden = false;
  }

  function clearError() {
    const el = $("error");
    el.textContent = "";
    el.hidden = true;
  }

  function reportError(what, e) {
    const detail = e instanceof ApiError && e.status ? " (HTTP " + e.status + ")" : "";
    showError(what + ": " + e.message + detail);
  }

  function busy(delta) {
    const n = Math.max(0, (parseInt(document.body.dataset.busy || "0", 10) || 0) + delta);
    document.body.dataset.busy = String(n);
  }

  // ------------------------------------------------------------------ formatting
  // the service writes +inf, -inf and NaN as the strings "Infinity", "-Infinity", "NaN"
  const NONFINITE = { "Infinity": Infinity, "-Infinity": -Infinity, "NaN": NaN };

  function num(x) {
    return typeof x === "string" && x in NONFINITE ? NONFINITE[x] : x;
  }

  function fmt(x, digits) {
    x = num(x);
    if (x === null || x === undefined) return "–";
    if (Number.isNaN(x)) return "NaN";
    if (typeof x !== "number") return String(x);
    if (!isFinite(x)) return x > 0 ? "∞" : "−∞";
    const d = digits === undefined ? 3 : digits;
    if (x !== 0 && (Math.abs(x) < 1e-3 || Math.abs(x) >= 1e5)) return x.toExponential(d - 1);
    return Number(x.toPrecision(d)).toString();
  }

  function esc(text) {
    const div = document.createElement("div");
    div.textContent = text === null || text === undefined ? "" : String(text);
    return div.innerHTML;
  }

  function table(rows) {
    return "<table>" + rows.map(([k, v, cls]) =>
      "<tr><th>" + esc(k) + "</th><td" + (cls ? " class=\"" + cls + "\"" : "") + ">" +
      v + "</td></tr>").join("") + "</table>";
  }

  // ------------------------------------------------------------------ plotting
  async function draw(div, traces, layout, source) {
    const full = Object.assign({}, BASE_LAYOUT, layout || {});
    // the message of an empty panel goes when the panel has data again
    div.querySelectorAll(":scope > p.note").forEach((el) => el.remove());
    await Plotly.react(div, traces, full, CONFIG);
    div.dataset.rendered = "1";
    div.dataset.source = source || "";
    div.dataset.version = String((parseInt(div.dataset.version || "0", 10) || 0) + 1);
  }

  function clearPlot(div, message) {
    Plotly.purge(div);
    div.dataset.rendered = "0";
    div.dataset.source = "";
    div.innerHTML = message ? "<p class=\"note\">" + esc(message) + "</p>" : "";
  }

  function centres(edges) {
    const out = [];
    for (let i = 0; i + 1 < edges.length; i++) out.push(0.5 * (edges[i] + edges[i + 1]));
    return out;
  }

  function widths(edges) {
    const out = [];
    for (let i = 0; i + 1 < edges.length; i++) out.push(edges[i + 1] - edges[i]);
    return out;
  }

  function bars(hist, name, color, key, extra) {
    const trace = Object.assign({
      type: "bar", name: name, x: centres(hist.edges), y: hist[key || "density"],
      width: widths(hist.edges), marker: { color: color, line: { width: 0 } },
      hovertemplate: "%{x:.3g}: %{y:.3g}<extra>" + name + "</extra>",
    }, extra || {});
    if (trace.width === null) delete trace.width;  // grouped bars: Plotly sizes them
    return trace;
  }

  function legend(box, items) {
    box.innerHTML = items.map(([label, color]) =>
      "<span class=\"swatch\" style=\"background:" + color + "\"></span>" + esc(label))
      .join(" ");
  }

  function cell(container, id) {
    let div = document.getElementById(id);
    if (!div) {
      div = document.createElement("div");
      div.id = id;
      div.className = "plot";
      container.appendChild(div);
    }
    return div;
  }

  // ------------------------------------------------------------------ lists
  async function loadLists() {
    const [ds, ms, cs] = await Promise.all([api("/datasets"), api("/models"),
                                            api("/catalogues")]);
    state.datasets = ds.datasets;
    state.models = ms.models;
    state.catalogues = cs.catalogues;
    fillSelect($("dataset-select"), state.datasets.map((d) =>
      [d.id, d.name + " (" + d.n_cutins + " cut-ins)"]));
    fillSelect($("model-select"), state.models.map((m) =>
      [m.id, m.id + (m["default"] ? " (default)" : "") + " · " + m.n_components +
              " components · " + m.dataset]));
    fillSelect($("catalogue-select"), [["", "— none —"]].concat(
      state.catalogues.slice().reverse().map((c) =>
        [c.id, c.id + " · n=" + c.n + " · seed " + c.seed + " · " + c.status])));
  }

  function fillSelect(select, options) {
    const keep = select.value;
    select.innerHTML = "";
    for (const [value, label] of options) {
      const opt = document.createElement("option");
      opt.value = value;
      opt.textContent = label;
      select.appendChild(opt);
    }
    if (options.some(([v]) => v === keep)) select.value = keep;
  }

  function setSelect(select, value) {
    select.value = value === null || value === undefined ? "" : value;
  }

  // ------------------------------------------------------------------ view 1
  async function loadFit() {
    if (!state.model) return;
    busy(1);
    try {
      const q = state.dataset ? "?dataset=" + encodeURIComponent(state.dataset) : "";
      const fit = await api("/dashboard/api/models/" + encodeURIComponent(state.model) +
                            "/fit" + q);
      state.fit = fit;
      $("fit-note").textContent = "Histograms of the " + fit.n_data + " cut-ins of " +
        fit.dataset_name + " with the marginal density of model " + fit.model + " (" +
        fit.n_components + " Gaussian components, " + fit.density_method + ").";
      legend($("fit-legend"), [["data (histogram)", COLORS.data], ["GMM marginal density",
                                                                   COLORS.model]]);
      const grid = $("fit-grid");
      for (const p of fit.parameters) {
        const div = cell(grid, "fit-" + p.name);
        const traces = [bars(p.histogram, "data", COLORS.data, "density",
                             { opacity: 0.6 })];
        const layout = { title: { text: p.name, font: { size: 12 } },
                         xaxis: { title: { text: p.label } },
                         yaxis: { title: { text: "density" } }, showlegend: false,
                         bargap: 0 };
        if (p.density) {
          traces.push({ type: "scatter", mode: "lines", name: "GMM marginal", x: p.density.x,
                        y: p.density.y, line: { color: COLORS.model, width: 2 } });
        } else {
          layout.annotations = [{ text: "not modelled (fixed at " + fmt(p.fixed) + ")",
                                  xref: "paper", yref: "paper", x: 0.5, y: 0.95,
                                  showarrow: false }];
        }
        await draw(div, traces, layout, fit.model);
      }
      if (!state.cornerParams) state.cornerParams = fit.corner["default"].slice();
      renderCornerChecks(fit);
      await drawCorner();
    } catch (e) {
      reportError("data against model", e);
    } finally {
      busy(-1);
    }
  }

  function renderCornerChecks(fit) {
    const box = $("corner-params");
    box.innerHTML = "Parameters: ";
    for (const name of fit.corner.names) {
      const label = document.createElement("label");
      const input = document.createElement("input");
      input.type = "checkbox";
      input.value = name;
      input.checked = state.cornerParams.includes(name);
      input.addEventListener("change", () => {
        state.cornerParams = Array.from(box.querySelectorAll("input:checked"))
          .map((el) => el.value);
        drawCorner();
      });
      label.appendChild(input);
      label.appendChild(document.createTextNode(" " + name));
      box.appendChild(label);
    }
  }

  async function drawCorner() {
    const fit = state.fit;
    const div = $("corner-plot");
    const names = PARAMS.filter((n) => state.cornerParams.includes(n));
    if (names.length < 2) {
      clearPlot(div, "Pick at least two parameters.");
      return;
    }
    const k = names.length - 1;
    const gap = 0.03;
    // axis titles: the name and its unit, e.g. "gap [m]" (the unit of the long label)
    const withUnit = (n) => {
      const m = /\[[^\]]*\]$/.exec((fit.corner.labels || {})[n] || "");
      return m ? n + " " + m[0] : n;
    };
    const size = (1 - gap * (k - 1)) / k;
    const traces = [];
    // the legend sits in the empty upper triangle
    const layout = { showlegend: true, margin: { l: 60, r: 12, t: 30, b: 50 },
                     hovermode: "closest",
                     legend: { x: 0.98, xanchor: "right", y: 0.98, orientation: "v",
                               font: { size: 12 }, itemsizing: "constant" } };
    let axis = 0;
    for (let row = 0; row < k; row++) {
      for (let col = 0; col <= row; col++) {
        axis += 1;
        const suffix = axis === 1 ? "" : String(axis);
        const xName = names[col];
        const yName = names[row + 1];
        const x0 = col * (size + gap);
        const y1 = 1 - row * (size + gap);
        layout["xaxis" + suffix] = {
          domain: [x0, x0 + size], anchor: "y" + suffix, tickfont: { size: 9 },
          title: row === k - 1 ? { text: withUnit(xName), font: { size: 11 } } : undefined,
          showticklabels: row === k - 1,
        };
        layout["yaxis" + suffix] = {
          domain: [y1 - size, y1], anchor: "x" + suffix, tickfont: { size: 9 },
          title: col === 0 ? { text: withUnit(yName), font: { size: 11 } } : undefined,
          showticklabels: col === 0,
        };
        for (const [group, color, opacity] of [["model", COLORS.model, 0.35],
                                               ["data", COLORS.data, 0.8]]) {
          const pts = fit.corner[group].values;
          traces.push({
            type: "scatter", mode: "markers", name: group === "data"
              ? "data (" + fit.corner.data.n_shown + ")"
              : "model samples (" + fit.corner.model.n_shown + ")",
            legendgroup: group, showlegend: axis === 1,
            x: pts[xName], y: pts[yName], xaxis: "x" + suffix, yaxis: "y" + suffix,
            marker: { size: 3, color: color, opacity: opacity },
            hovertemplate: xName + " %{x:.3g}<br>" + yName + " %{y:.3g}<extra>" + group +
              "</extra>",
          });
        }
      }
    }
    await draw(div, traces, layout, fit.model);
  }

  // ------------------------------------------------------------------ view 2
  async function loadShift() {
    busy(1);
    try {
      let view;
      if (state.catalogue) {
        view = await prefetched("/dashboard/api/catalogues/" +
                                encodeURIComponent(state.catalogue) + "/shift");
      } else {
        if (!state.model) return;
        const constraint = $("constraint-input").value;
        const seed = parseInt($("seed-input").value, 10) || 0;
        view = await api("/dashboard/api/models/" + encodeURIComponent(state.model) +
                         "/shift?constraints=" + encodeURIComponent(constraint) +
                         "&n=1000&seed=" + seed);
      }
      const what = view.constraints.length ? view.constraints.join(" and ") : "no constraint";
      const pa = view.p_region && view.p_region.estimate !== undefined
        ? "; P(A) = " + fmt(view.p_region.estimate) : "";
      $("shift-note").textContent = (view.source === "catalogue"
        ? "Catalogue " + view.catalogue + ": its " + view.n + " samples (" + what + ")"
        : "Preview: " + view.n + " samples of model " + view.model + " with " + what +
          " (not scored; draw a catalogue to score them)") +
        " against " + view.n_reference + " model samples inside the physical bounds only" +
        pa + ". Bars are densities on common bins.";
      legend($("shift-legend"), [["unconstrained (model, physical bounds only)",
                                  COLORS.unconstrained], ["constrained", COLORS.constrained]]);
      const grid = $("shift-grid");
      const source = view.source === "catalogue" ? view.catalogue : "preview:" + what;
      for (const p of view.parameters) {
        const div = cell(grid, "shift-" + p.name);
        const shift = p.mean_constrained !== null && p.mean_unconstrained !== null
          ? " (mean " + fmt(p.mean_unconstrained) + " → " + fmt(p.mean_constrained) + ")" : "";
        await draw(div, [
          bars(p.unconstrained, "unconstrained", COLORS.unconstrained, "density",
               { opacity: 0.55 }),
          bars(p.constrained, "constrained", COLORS.constrained, "density", { opacity: 0.55 }),
        ], {
          barmode: "overlay", bargap: 0, showlegend: false,
          title: { text: p.name + shift, font: { size: 11 } },
          xaxis: { title: { text: p.label } }, yaxis: { title: { text: "density" } },
        }, source);
      }
    } catch (e) {
      // the preview runs when the constraint field loses focus (e.g. on "Draw"): a bad
      // constraint is marked here too, whichever of the two answers arrives first
      if (!state.catalogue && e.field && e.field.indexOf("constraints") >= 0) {
        $("constraint-input").classList.add("invalid");
      }
      reportError("constrained against unconstrained", e);
    } finally {
      busy(-1);
    }
  }

  // ------------------------------------------------------------------ view 3
  const CLASS_COLORS = { no_conflict: "#7cb342", preventable: "#1f5fbf",
                         unpreventable: "#e07b00", unavoidable: "#b3261e" };
  const DRIVER_COLORS = { none: "#8a94a3", r157_cc: "#1f5fbf", rss: "#6a1b9a" };
  const CLASS_LABELS = {
    no_conflict: "no conflict (no collision without reaction)",
    preventable: "preventable (careful driver avoids it)",
    unpreventable: "unpreventable (careful driver collides; some manoeuvre avoids it)",
    unavoidable: "unavoidable (nothing avoids it)",
  };
  const VIEW3_PLOTS = ["class-counts", "ttc-btn", "btn-hist", "ttr-hist", "impact-hist",
                       "rdep-hist", "alarm-hist"];

  // "name (what it means, …)" as "name<br>(what it means,<br>…)": readable tick labels
  function wrapLabel(text, width) {
    const words = text.split(" ");
    const lines = [];
    let line = "";
    for (const w of words) {
      if (line && (line + " " + w).length > width) {
        lines.push(line);
        line = w;
      } else {
        line = line ? line + " " + w : w;
      }
    }
    if (line) lines.push(line);
    return lines.join("<br>");
  }

  function note(text) {
    return { text: text, xref: "paper", yref: "paper", x: 0.98, y: 0.97, showarrow: false,
             xanchor: "right", yanchor: "top", align: "right",
             bgcolor: "rgba(255,255,255,0.85)", font: { size: 10 } };
  }

  function vline(x, text) {
    return {
      shape: { type: "line", x0: x, x1: x, yref: "paper", y0: 0, y1: 1,
               line: { color: "#333", width: 1, dash: "dash" } },
      annotation: { text: text, x: x, xref: "x", yref: "paper", y: 0.8, yanchor: "top",
                    xanchor: "right", align: "right", showarrow: false, font: { size: 10 },
                    bgcolor: "rgba(255,255,255,0.85)" },
    };
  }

  // a histogram of counts, or a message saying why there is nothing to draw
  async function histogramPanel(div, hist, spec, source) {
    if (!hist.n_finite) {
      clearPlot(div, spec.empty);
      return;
    }
    const traces = [bars(hist, spec.name, spec.color, "counts")].concat(spec.extra || []);
    await draw(div, traces, Object.assign({
      bargap: 0.05, showlegend: false,
      title: { text: spec.title, font: { size: 12 } },
      xaxis: { title: { text: spec.x } },
      // head room above the tallest bar for the notes in the upper right corner
      yaxis: { title: { text: "scenarios" }, range: [0, 1.2 * Math.max(1, ...hist.counts)] },
      annotations: spec.notes ? [note(spec.notes.join("<br>"))] : [],
    }, spec.layout || {}), source);
  }

  async function loadRisk() {
    const divs = VIEW3_PLOTS.map($);
    if (!state.catalogue) {
      $("risk-note").textContent = "No catalogue selected: pick one above or draw a new " +
        "sample (constraint, n, seed → Draw new sample).";
      $("catalogue-info").innerHTML = "";
      $("top-table").innerHTML = "";
      divs.forEach((d) => clearPlot(d, "No catalogue yet: pick one above, or draw a new " +
                                       "sample (constraint, n, seed, then Draw new sample)."));
      return;
    }
    busy(1);
    try {
      const id = state.catalogue;
      const view = await prefetched("/dashboard/api/catalogues/" + encodeURIComponent(id) +
                                    "/criticality");
      if (id !== state.catalogue) return;
      const c = view.catalogue;
      const d = view.diagnostics;
      const pr = c.p_region || {};
      if (!pr.ci && pr.ci_low !== undefined && pr.ci_high !== undefined) {
        pr.ci = [pr.ci_low, pr.ci_high];
      }
      const sc = view.scatter;
      $("risk-note").textContent = "Catalogue " + c.id + " (" + c.status + "): " +
        view.n_rows + " scenarios stored, " + view.n_scored + " with a criticality record" +
        (view.n_unscored ? " (" + view.n_unscored + " without: not scored or refused by " +
                           "the builder)" : "") + ". Histograms are counted and the " +
        "scatter thinned on the server (" + sc.n_shown + " of " + sc.n_plottable +
        " points shown: " + sc.selection + "). Classes and fields: docs/criticality.md.";
      const rows = [
        ["constraints", esc(c.constraints.join(" and ") || "none")],
        ["n · seed", esc(c.n + " · " + c.seed)],
        ["model", esc(c.model)],
        ["P(A)", esc(fmt(pr.estimate, 4) + (pr.ci ? "  (95% CI " + fmt(pr.ci[0], 3) + " – " +
                                                     fmt(pr.ci[1], 3) + ", " +
                                                     (pr.method || "") + ")" : ""))],
        ["data support", esc(supportText(c.support))],
        ["sampler", esc(c.sampler + (d.methods.length ? " → " + d.methods.join(", ") : "") +
                        " over " + d.chunks + " chunk(s)")],
        ["acceptance", esc("mean " + fmt(d.acceptance_mean) + ", min " +
                           fmt(d.acceptance_min))],
        ["τ (max)", esc(fmt(d.tau_max) + (d.tau_max === null ? " (no MCMC chain)" : ""))],
        ["effective sample size", esc(fmt(d.ess_total, 4))],
      ];
      if (c.status !== "done") rows.push(["progress", esc(progressText(c))]);
      if (c.stage) rows.push(["stage", esc(stageText(c.stage))]);
      if (c.status === "done") {
        const href = "/catalogues/" + encodeURIComponent(c.id) + "/export?format=";
        rows.push(["export", ["jsonl", "csv", "parquet", "xosc"].map((f) =>
          "<a href=\"" + href + f + "\" download data-export=\"" +
          esc(c.id + "." + (f === "xosc" ? "zip" : f)) + "\">" + f + "</a>").join(" · ")]);
      }
      if (c.error) rows.push(["error", esc(c.error), "warn"]);
      for (const w of d.warnings) rows.push(["warning", esc(w), "warn"]);
      $("catalogue-info").innerHTML = table(rows);

      if (!view.n_scored) {
        const why = "No scenario of this catalogue has a criticality record (drawn without " +
          "scoring, or every vector was refused by the builder): draw a new sample with " +
          "scoring to see the classes and margins.";
        divs.forEach((div) => clearPlot(div, why));
        $("top-table").innerHTML = "<p class=\"note\">" + esc(why) + "</p>";
        if (c.status === "queued" || c.status === "running") schedulePoll(id);
        return;
      }
      await drawClasses(divs[0], view, id);
      await drawTtcBtn(divs[1], view, id);
      const dm = view.decel_max;
      const btn = view.btn;
      const edges = btn.edges;
      const one = vline(1, "btn = 1: full braking <br>of the careful driver ");
      await histogramPanel(divs[2], btn, {
        name: "btn", color: "#455a64",
        title: "Brake threat number at perception (btn = a_req / " + fmt(dm) + " m/s²)",
        x: "btn: constant deceleration needed from t_p + 0.75 s, over 0.774 g",
        empty: "No finite btn: " + btn.n_inf + " scenario(s) collide before the careful " +
          "driver could brake (btn = ∞).",
        layout: {
          // a_req in m/s² on the top axis: the same bars, scaled by decel_max
          xaxis: { title: { text: "btn: constant deceleration needed from t_p + 0.75 s, " +
                                  "over 0.774 g" }, range: [edges[0], edges[edges.length - 1]] },
          xaxis2: { title: { text: "a_req [m/s²]", standoff: 2 }, overlaying: "x",
                    side: "top", range: [edges[0] * dm, edges[edges.length - 1] * dm] },
          margin: { l: 48, r: 12, t: 64, b: 42 },
          shapes: [one.shape],
          annotations: [note(btn.n_inf + " with btn = ∞ (contact before t_p + 0.75 s)<br>" +
                             "btn = 0: no collision at constant speed"), one.annotation],
        },
        // an invisible point on the top axis, so that plotly draws it
        extra: [{ type: "scatter", x: [edges[0] * dm], y: [0], xaxis: "x2", mode: "markers",
                  hoverinfo: "skip", marker: { opacity: 0 }, showlegend: false }],
      }, id);
      const ttr = view.ttr_true;
      await histogramPanel(divs[3], ttr, {
        name: "ttr_true", color: "#00796b",
        title: "Time to react at perception, true cutter path (ttr_true)",
        x: "ttr_true: latest reaction after t_p that still avoids it [s] (0 = nothing does)",
        empty: "No finite ttr_true: " + ttr.n_inf + " scenario(s) have no collision at " +
          "constant speed (ttr_true = ∞).",
        notes: [ttr.n_inf + " with no collision at constant speed (ttr_true = ∞)"]
          .concat(ttr.n_null ? [ttr.n_null + " without t_p (not a cut-in seen)"] : []),
      }, id);
      await drawImpact(divs[4], view, id);
      await drawRiskAtTp(divs[5], view, id);
      const alarm = view.alarm_time;
      await histogramPanel(divs[6], alarm, {
        name: "alarm time", color: "#8e24aa",
        title: "Alarm time: from t_p until Wagner's r_dep first reaches 0.5",
        x: "alarm time after t_p [s] (scripted ego)",
        empty: "r_dep never reaches 0.5 in any scenario of this catalogue (" + alarm.n_null +
          " scenario(s)): an online predictor would raise no alarm.",
        notes: [alarm.n_null + " never reach 0.5 (up to the contact)"],
      }, id);
      drawTop(view, id);
      if (c.status === "queued" || c.status === "running") schedulePoll(id);
    } catch (e) {
      reportError("catalogue " + state.catalogue, e);
      divs.forEach((d) => clearPlot(d, "This catalogue could not be shown (the message " +
                                       "above says why): pick another one or draw a new sample."));
      $("top-table").innerHTML = "";
    } finally {
      busy(-1);
    }
  }

  // how many scenarios the real cut-ins support (docs/sampler.md, "Data support")
  function supportText(counts) {
    const names = Object.keys(counts || {});
    const total = names.reduce((a, k) => a + counts[k], 0);
    if (!total) return "– (no scenario stored yet)";
    return names.map((k) => k + " " + counts[k] + " (" + fmt(100 * counts[k] / total, 2) +
                     " %)").join(" · ") + " — inside: within the range of the real " +
      "cut-ins; extrapolated: the model's invention";
  }

  async function drawClasses(div, view, id) {
    const total = view.classes.reduce((a, k) => a + k.count, 0);
    const counts = view.classes.map((k) => k.count);
    const top = Math.max(1, ...counts);
    // a class with a handful of scenarios beside one with hundreds is a bar of one pixel:
    // then the counts go on a log axis (a lone unpreventable cut-in was invisible)
    const log = counts.some((c) => c > 0 && c < 0.01 * top);
    const label = (c) => c + " (" + fmt(total ? 100 * c / total : 0, 3) + "%)";
    const x = view.classes.map((k) => wrapLabel(k.label, 24));
    await draw(div, [{
      type: "bar", x: x,
      y: log ? counts.map((c) => (c > 0 ? c : null)) : counts,
      customdata: view.classes.map((k) => k.name),
      text: counts.map((c) => (log && c === 0 ? "" : label(c))),
      textposition: "outside", cliponaxis: false,
      marker: { color: view.classes.map((k) => CLASS_COLORS[k.name]) },
      hovertemplate: "%{customdata}: %{y} scenarios<extra></extra>",
    }], { title: { text: "Criticality classes (" + total + " scored scenarios)" +
                         (log ? ", log scale" : ""), font: { size: 12 } },
          yaxis: log ? { title: { text: "scenarios (log scale)" }, type: "log", dtick: 1,
                         range: [Math.log10(0.5), Math.log10(top * 4)] }
            : { title: { text: "scenarios" }, rangemode: "tozero" },
          // on the log axis an empty class has no bar: its "0" is written at the bottom
          annotations: log ? counts.map((c, i) => (c > 0 ? null : {
            x: x[i], y: Math.log10(0.7), text: label(0), showarrow: false,
            font: { size: 11 } })).filter((a) => a) : [],
          xaxis: { automargin: true, tickfont: { size: 10 } },
          margin: { l: 48, r: 12, t: 36, b: 20 }, showlegend: false }, id);
  }

  async function drawTtcBtn(div, view, id) {
    const s = view.scatter;
    if (!s.n_shown) {
      clearPlot(div, "No scenario with a finite TTC and btn to plot (" + s.n_ttc_inf +
                " with TTC = ∞, " + s.n_btn_inf + " with btn = ∞).");
      return;
    }
    const traces = view.classes.map((k) => {
      const pick = [];
      s.cls.forEach((c, i) => { if (c === k.name) pick.push(i); });
      return {
        type: "scatter", mode: "markers", name: k.name.replace("_", " "),
        x: pick.map((i) => s.ttc[i]), y: pick.map((i) => s.btn[i]),
        customdata: pick.map((i) => s.index[i]),
        marker: { size: 7, color: CLASS_COLORS[k.name], opacity: 0.8,
                  line: { width: 0.5, color: "#333" } },
        hovertemplate: "scenario %{customdata}<br>TTC %{x:.2f} s<br>btn %{y:.3f}" +
          "<extra>" + k.name + " · click to open</extra>",
      };
    }).filter((t) => t.x.length);
    const inf = [];
    if (s.n_ttc_inf) inf.push(s.n_ttc_inf + " with TTC = ∞ not shown");
    if (s.n_btn_inf) inf.push(s.n_btn_inf + " with btn = ∞ not shown");
    await draw(div, traces, {
      title: { text: "TTC against btn, by class (click a point to open it)",
               font: { size: 12 } },
      hovermode: "closest",
      legend: { orientation: "h", y: -0.22, x: 0, font: { size: 10 } },
      xaxis: { title: { text: "TTC at the crossing [s]" }, rangemode: "tozero" },
      yaxis: { title: { text: "btn (1 = careful driver's full braking)" }, rangemode: "tozero" },
      margin: { l: 52, r: 12, t: 30, b: 70 },
      // btn = 1: the careful driver's full braking
      shapes: [{ type: "line", xref: "paper", x0: 0, x1: 1, yref: "y", y0: 1, y1: 1,
                 line: { color: "#333", width: 1, dash: "dash" } }],
      annotations: inf.length ? [note(inf.join("<br>"))] : [],
    }, id);
    div.removeAllListeners && div.removeAllListeners("plotly_click");
    div.on("plotly_click", (ev) => {
      const pt = ev && ev.points && ev.points[0];
      if (pt && pt.customdata !== undefined) openScenario(state.catalogue, pt.customdata);
    });
  }

  async function drawImpact(div, view, id) {
    const drivers = view.impact_speed;
    const hits = drivers.filter((d) => d.histogram.n > 0);
    if (!hits.length) {
      clearPlot(div, "No reference driver collides in this catalogue, not even the " +
                "non-reacting one: no impact speeds to show.");
      return;
    }
    const n = view.n_scored;
    // only the drivers that collide get bars (an empty driver's share of each group made
    // the others' bars a comb of thin lines); the others are named in a note
    const none = drivers.filter((d) => d.histogram.n === 0)
      .map((d) => d.label + ": 0 of " + n + " collide");
    await draw(div, hits.map((d) => bars(
      d.histogram, d.label + ": " + d.histogram.n + " of " + n + " collide",
      DRIVER_COLORS[d.driver], "counts", { width: null })), {
      barmode: "group", bargap: 0.08, bargroupgap: 0,
      title: { text: "Impact speed of the colliding scenarios, per reference driver",
               font: { size: 12 } },
      legend: { orientation: "h", x: 0, y: -0.22, font: { size: 10 } },
      showlegend: true,
      margin: { l: 48, r: 12, t: 30, b: 78 },
      xaxis: { title: { text: "relative speed at contact [m/s]" } },
      yaxis: { title: { text: "scenarios" } },
      annotations: none.length ? [note(none.join("<br>"))] : [],
    }, id);
  }

  // r_dep at t_p on a log axis: most cut-ins have exactly 0 at t_p (the first bin,
  // [0, 1e-8), is counted in the legend, not drawn: as a bar it flattened the others), the
  // others spread over seven decades in half-decade bins
  async function drawRiskAtTp(div, view, id) {
    const h = view.r_dep_tp;
    if (!h.scripted.n_finite) {
      clearPlot(div, "No scenario has Wagner's risk at t_p (no perception moment found).");
      return;
    }
    const trace = (hist, name, color) => {
      const e = hist.edges.slice(1).map((v) => Math.log10(v));
      return { type: "bar", name: name + ": " + hist.counts[0] + " of " + hist.n_finite +
               " below 1e-8 (most exactly 0), not drawn",
               x: centres(e), y: hist.counts.slice(1), marker: { color: color },
               customdata: hist.counts.slice(1).map((_, i) => fmt(hist.edges[i + 1], 2) +
                                                     " … " + fmt(hist.edges[i + 2], 2)),
               hovertemplate: "r_dep %{customdata}: %{y} scenarios<extra>" + name +
                 "</extra>" };
    };
    const low = Math.round(Math.log10(h.scripted.edges[1]));
    const ticks = [];
    for (let k = low; k <= 0; k++) ticks.push(k);
    const drawn = h.scripted.counts.slice(1).concat(h.r157.counts.slice(1));
    await draw(div, [
      trace(h.scripted, "scripted ego", COLORS.r_dep),
      trace(h.r157, "R157 driver's ego", COLORS.r_ind),
    ], {
      barmode: "group", bargap: 0.1, bargroupgap: 0,
      title: { text: "Wagner's risk r_dep at the perception moment t_p (log scale)",
               font: { size: 12 } },
      legend: { orientation: "h", x: 0, y: -0.22, font: { size: 10 } },
      margin: { l: 48, r: 12, t: 30, b: 78 },
      xaxis: { title: { text: "r_dep at t_p (half-decade bins)" }, tickvals: ticks,
               ticktext: ticks.map((k) => (k === 0 ? "1" : "1e" + k)), range: [low, 0] },
      yaxis: { title: { text: "scenarios" }, range: [0, 1.15 * Math.max(1, ...drawn)] },
    }, id);
  }

  // The riskiest scenarios: the catalogue's first 10 by btn (from the view), then any
  // order and filter the user picks (GET /catalogues/{id}/scenarios sorts and filters the
  // whole catalogue on the server). Columns that sort: a click on the header.
  const TOP_COLUMNS = [
    ["index", "#", "index"], ["class", "class", null], ["btn", "btn", "btn"],
    ["a_req", "a_req [m/s²]", "a_req"], ["ttr_true", "ttr_true [s] (manoeuvre)", "ttr_true"],
    ["ttc", "TTC [s]", "ttc"], ["support", "data support", null],
    ["r157", "R157 driver", "r157_cc_impact_speed"],
  ];
  const SUPPORT_CHOICES = [["", "any"], ["inside", "inside"], ["near", "near"],
                           ["extrapolated", "extrapolated"],
                           ["inside,near", "inside or near (not extrapolated)"]];
  const top = { order: "btn", desc: true, cls: "", support: "", version: 0 };

  function topRow(r) {
    const r157 = r.r157_cc_collision === null || r.r157_cc_collision === undefined ? "–"
      : r.r157_cc_collision ? "collides at " + fmt(num(r.r157_cc_impact_speed)) + " m/s"
        : "avoids it";
    const ttc = r.ttc === null ? Infinity : num(r.ttc);
    return "<tr data-index=\"" + r.index + "\"><td><a href=\"?scenario=" + r.index + "\">" +
      r.index + "</a></td><td><span class=\"swatch\" style=\"background:" +
      (CLASS_COLORS[r["class"]] || "#999") + "\"></span>" + esc(r["class"] || "–") +
      "</td><td>" + esc(fmt(num(r.btn))) + "</td><td>" + esc(fmt(num(r.a_req))) + "</td><td>" +
      esc(fmt(num(r.ttr_true)) + (r.ttr_manoeuvre ? " (" + r.ttr_manoeuvre + ")" : "")) +
      "</td><td>" + esc(fmt(ttc)) + "</td><td>" + esc(r.support || "–") + "</td><td>" +
      esc(r157) + "</td></tr>";
  }

  function renderTop(rows, total, id) {
    const box = $("top-table");
    const sortName = (TOP_COLUMNS.find((c) => c[2] === top.order) || [null, top.order])[1];
    const filtered = top.cls || top.support;
    const title = "The first " + rows.length + " of " + (total === null ? "the catalogue"
      : total + (filtered ? " matching" : "")) + " by " + sortName +
      (top.desc ? ", highest first" : ", lowest first") + " (click a row to open it, a " +
      "column's header to sort by it)";
    const opts = (choices, value) => choices.map(([v, label]) => "<option value=\"" + esc(v) +
      "\"" + (v === value ? " selected" : "") + ">" + esc(label) + "</option>").join("");
    const classes = [["", "any"]].concat(Object.keys(CLASS_COLORS).map((k) => [k, k]));
    const head = TOP_COLUMNS.map(([, label, key]) => key
      ? "<th class=\"sortable" + (key === top.order ? " sorted" : "") + "\" data-order=\"" +
        key + "\" title=\"sort by " + esc(label) + "\">" + esc(label) +
        (key === top.order ? (top.desc ? " ▼" : " ▲") : "") + "</th>"
      : "<th>" + esc(label) + "</th>").join("");
    box.innerHTML = "<h3>" + esc(title) + "</h3>" +
      "<div class=\"top-filters\"><label>class <select id=\"top-class\">" +
      opts(classes, top.cls) + "</select></label> <label>data support <select " +
      "id=\"top-support\">" + opts(SUPPORT_CHOICES, top.support) + "</select></label></div>" +
      "<div class=\"scroll\"><table class=\"rank\"><tr>" + head + "</tr>" +
      (rows.length ? rows.map(topRow).join("")
        : "<tr><td colspan=\"" + TOP_COLUMNS.length + "\">no scenario matches</td></tr>") +
      "</table></div>";
    box.dataset.source = id;
    box.dataset.order = top.order + (top.desc ? " desc" : " asc");
    for (const link of box.querySelectorAll("a")) {
      link.addEventListener("click", (ev) => {
        ev.preventDefault();
        openScenario(state.catalogue, parseInt(link.textContent, 10));
      });
    }
    for (const th of box.querySelectorAll("th.sortable")) {
      th.addEventListener("click", () => {
        const key = th.dataset.order;
        top.desc = key === top.order ? !top.desc : key !== "index" && key !== "ttc";
        top.order = key;
        loadTop(id);
      });
    }
    $("top-class").addEventListener("change", (e) => { top.cls = e.target.value; loadTop(id); });
    $("top-support").addEventListener("change", (e) => {
      top.support = e.target.value;
      loadTop(id);
    });
  }

  function drawTop(view, id) {
    if ($("top-table").dataset.source !== id) {  // another catalogue: its first 10 by btn
      Object.assign(top, { order: "btn", desc: true, cls: "", support: "" });
    }
    if (!view.top.length) {
      $("top-table").innerHTML = "<p class=\"note\">No scored scenario to rank.</p>";
      return;
    }
    if (top.order === "btn" && top.desc && !top.cls && !top.support) {
      renderTop(view.top, null, id);  // the view's own first 10: no extra request
    } else {
      loadTop(id);
    }
  }

  async function loadTop(id) {
    const version = ++top.version;
    const q = new URLSearchParams({ limit: "10", order_by: top.order, desc: String(top.desc) });
    if (top.cls) q.append("class", top.cls);
    for (const s of top.support ? top.support.split(",") : []) q.append("support", s);
    busy(1);
    try {
      const page = await api("/catalogues/" + encodeURIComponent(id) + "/scenarios?" + q);
      if (version !== top.version || id !== state.catalogue) return;
      renderTop(page.scenarios, page.total, id);
    } catch (e) {
      reportError("the riskiest scenarios", e);
    } finally {
      busy(-1);
    }
  }

  // ------------------------------------------------------------------ view 4
  function box(x, y, psi, length, width) {
    const c = Math.cos(psi);
    const s = Math.sin(psi);
    const pts = [[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5], [0.5, 0.5]];
    return {
      x: pts.map(([a, b]) => x + a * length * c - b * width * s),
      y: pts.map(([a, b]) => y + a * length * s + b * width * c),
    };
  }

  async function openScenario(catalogue, index) {
    stopPlay();
    busy(1);
    try {
      $("scenario-note").textContent = "Loading scenario " + index + " (computing its risk " +
        "over time)…";
      const sc = await api("/dashboard/api/catalogues/" + encodeURIComponent(catalogue) +
                           "/scenarios/" + encodeURIComponent(index));
      state.scenario = sc;
      const url = "/dashboard/catalogues/" + encodeURIComponent(catalogue) + "?scenario=" +
        sc.index;
      setUrl(url, false);
      const sm = sc.summary;
      const rec = sc.record;
      const prof = sc.profiles;
      $("scenario-note").textContent = "Scenario " + sc.index + " of catalogue " +
        sc.catalogue + " (" + sc.trajectory_source + ")" + (prof ? "." : "; Wagner's " +
        "risk of the R157 driver's ego could not be computed: " + sc.profiles_error);
      const s = (x) => fmt(x) + " s";
      const driver = (name) => {
        const hit = rec[name + "_collision"];
        if (hit === null || hit === undefined) return "–";
        const brake = rec[name + "_t_brake"];
        return (hit ? "collides at " + fmt(rec[name + "_impact_speed"]) + " m/s"
          : "avoids it, smallest gap " + fmt(rec[name + "_min_gap"]) + " m") +
          (brake === undefined ? "" : brake === null ? ", never brakes"
            : ", brakes from t = " + s(brake));
      };
      const label = CLASS_LABELS[rec["class"]] || "not scored" +
        (rec.error ? ": " + rec.error : "");
      $("scenario-info").innerHTML = table([
        ["class", "<span class=\"swatch\" style=\"background:" +
          (CLASS_COLORS[rec["class"]] || "#999") + "\"></span>" + esc(label)],
        ["btn · a_req", esc(fmt(rec.btn) + " · " + fmt(rec.a_req) + " m/s² (braking from " +
                            "t_p + 0.75 s)")],
        ["ttr_true (manoeuvre)", esc(s(rec.ttr_true) + " after t_p (" +
          (rec.ttr_manoeuvre === null ? "no collision at constant speed"
            : rec.ttr_manoeuvre === "none" ? "nothing avoids it" : rec.ttr_manoeuvre) + ")")],
        ["t_p · crossing · TTC", esc("perceivable at t = " + s(rec.t_p) + ", crosses the " +
                                     "marking at t = " + s(rec.t_cross) + ", TTC " +
                                     s(rec.ttc))],
        ["no reaction", esc(driver("none"))],
        ["R157 careful driver", esc(driver("r157_cc"))],
        ["RSS response", esc(driver("rss"))],
        ["Wagner's r_dep", esc("at t_p " + fmt(rec.r_dep_tp) + " (R157 ego " +
                               fmt(rec.r_dep_tp_r157) + "), at the crossing " +
                               fmt(rec.r_dep_cross) + " (R157 ego " + fmt(rec.r_dep_cross_r157) +
                               "), peak " + fmt(rec.risk_peak) + "; alarm (r_dep ≥ 0.5) " +
                               (rec.alarm_time === null ? "never"
                                 : s(rec.alarm_time) + " after t_p"))],
        ["parameters", esc(PARAMS.map((p) => p + " " + fmt(sc.params[p])).join(", "))],
      ]);
      const slider = $("time-slider");
      slider.max = String(sc.t.length - 1);
      // start at the perception moment (else the highest risk)
      const tp = num(rec.t_p);
      const atTp = typeof tp === "number" && isFinite(tp)
        ? sc.t.findIndex((t) => t >= tp - 1e-9) : -1;
      const start = Math.min(sc.t.length - 1,
                             Math.max(0, atTp >= 0 ? atTp : sm.step_of_max_risk || 0));
      slider.value = String(start);
      // the plots are hidden until a scenario is opened (empty, they only pushed view
      // 4's evaluation run panel down)
      $("slider-row").hidden = false;
      $("topdown-plot").hidden = false;
      $("series-plot").hidden = false;
      await drawScenario(start);
      $("view-scenario").scrollIntoView({ block: "start" });
    } catch (e) {
      reportError("scenario " + index, e);
    } finally {
      busy(-1);
    }
  }

  async function drawScenario(k) {
    const sc = state.scenario;
    const source = sc.catalogue + "#" + sc.index;
    const lw = sc.lane_width || 3.75;
    const xs = [sc.ego.x].concat(sc.objects.map((o) => o.x)).flat();
    // the markings span every view the time slider can show (it follows the ego from 35 m
    // behind to 85 m ahead), not only the tracks
    const xmin = Math.min.apply(null, xs) - 40;
    const xmax = Math.max.apply(null, xs) + 90;
    const traces = [];
    for (const [y, dash] of [[-1.5 * lw, "solid"], [-0.5 * lw, "dash"], [0.5 * lw, "dash"],
                             [1.5 * lw, "solid"]]) {
      traces.push({ type: "scatter", mode: "lines", x: [xmin, xmax], y: [y, y],
                    line: { color: "#9aa3ad", width: 1, dash: dash }, hoverinfo: "skip",
                    showlegend: false });
    }
    const prof = sc.profiles;
    const tracks = [["ego (scripted)", sc.ego, COLORS.ego, false]].concat(
      sc.objects.map((o) => [o.id, o, COLORS.cutter, false]));
    if (prof) {
      // the R157 careful driver's reacted ego: the scripted one until it brakes
      // the same car as the scripted ego: a size the profile lacks (null) is the ego's
      const r157 = Object.assign({}, prof.r157_ego);
      if (r157.length === null || r157.length === undefined) r157.length = sc.ego.length;
      if (r157.width === null || r157.width === undefined) r157.width = sc.ego.width;
      tracks.push(["ego (R157 driver)", r157, COLORS.r157, true]);
    }
    for (const [name, tr, color, reacted] of tracks) {
      traces.push({ type: "scatter", mode: "lines", name: name + " path", x: tr.x, y: tr.y,
                    line: { color: color, width: reacted ? 1.5 : 1, dash: reacted ? "dash" : "dot" },
                    showlegend: false, hoverinfo: "skip" });
    }
    for (const [name, tr, color, reacted] of tracks) {
      const b = box(tr.x[k], tr.y[k], tr.psi[k], tr.length, tr.width);
      traces.push({ type: "scatter", mode: "lines", name: name, x: b.x, y: b.y,
                    fill: "toself", fillcolor: reacted ? "rgba(46,125,50,0.25)" : color,
                    line: { color: color, width: reacted ? 2 : 1, dash: reacted ? "dash" : "solid" },
                    hovertemplate: name + " v %{customdata:.1f} m/s<extra></extra>",
                    customdata: b.x.map(() => tr.v[k]) });
    }
    const cx = sc.ego.x[k];
    await draw($("topdown-plot"), traces, {
      title: { text: "Top-down view at t = " + fmt(sc.t[k]) + " s" + (prof
        ? " (dashed green: the ego of the R157 careful driver, braking from t = " +
          fmt(prof.r157_t_brake) + " s)" : ""), font: { size: 12 } },
      xaxis: { title: { text: "x along the road [m]" }, range: [cx - 35, cx + 85] },
      yaxis: { title: { text: "y [m]" }, range: [-2 * lw, 2 * lw], scaleanchor: "x",
               scaleratio: 1 },
      margin: { l: 48, r: 12, t: 30, b: 40 }, showlegend: true,
      legend: { orientation: "h", y: 1.0, x: 1, xanchor: "right", yanchor: "bottom",
                font: { size: 10 } },
    }, source);

    const s = sc.series;
    const cap = (arr) => arr.map((v) => (v === null ? null : Math.min(v, 10)));
    const traces2 = [
      { type: "scatter", mode: "lines", name: "r_dep, scripted ego", x: s.t, y: s.r_dep,
        line: { color: COLORS.r_dep, width: 2.5 } },
      { type: "scatter", mode: "lines", name: "r_ind, scripted ego", x: s.t, y: s.r_ind,
        line: { color: COLORS.r_ind, width: 1.5, dash: "dot" } },
    ];
    if (prof) {
      traces2.push({ type: "scatter", mode: "lines", name: "r_dep, R157 driver's ego",
                     x: prof.t, y: prof.r_dep_r157,
                     line: { color: COLORS.r157, width: 2.5, dash: "dash" } });
    }
    traces2.push(
      { type: "scatter", mode: "lines", name: "TTC", x: s.t, y: cap(s.ttc), yaxis: "y2",
        line: { color: COLORS.ttc, width: 1 } },
      { type: "scatter", mode: "lines", name: "WTTC", x: s.t, y: cap(s.wttc), yaxis: "y2",
        line: { color: COLORS.wttc, width: 1 } },
      { type: "scatter", mode: "lines", name: "THW", x: s.t, y: cap(s.thw), yaxis: "y2",
        line: { color: COLORS.thw, width: 1 } });
    // vertical lines: the slider's time, t_p, the crossing and the R157 braking start
    const shapes = [{ type: "line", x0: s.t[k], x1: s.t[k], yref: "paper", y0: 0, y1: 1,
                      line: { color: "#333", width: 1, dash: "dash" } }];
    const annotations = [];
    const marks = prof ? [["t_p", prof.t_p, "#000"], ["crossing", prof.t_cross, "#555"],
                          ["R157 brakes", prof.r157_t_brake, COLORS.r157]] : [];
    marks.forEach(([text, t, color], i) => {
      if (t === null || t === undefined) return;
      shapes.push({ type: "line", name: text, x0: t, x1: t, yref: "paper", y0: 0, y1: 1,
                    line: { color: color, width: 1.5 } });
      annotations.push({ text: text, x: t, xref: "x", yref: "paper", y: 1 - 0.09 * i,
                         yanchor: "top", xanchor: "left", showarrow: false,
                         font: { size: 10, color: color }, bgcolor: "rgba(255,255,255,0.8)" });
    });
    await draw($("series-plot"), traces2, {
      title: { text: "Wagner's risk over time, scripted and R157 driver's ego, with TTC, WTTC " +
                     "and THW (capped at 10 s; gaps: not defined)", font: { size: 12 } },
      xaxis: { title: { text: "t [s]" } },
      yaxis: { title: { text: "risk" }, range: [0, 1.02] },
      yaxis2: { title: { text: "TTC, WTTC, THW [s]" }, overlaying: "y", side: "right", range: [0, 10.2] },
      margin: { l: 48, r: 48, t: 30, b: 80 },
      legend: { orientation: "h", y: -0.2, x: 0, font: { size: 10 } },
      shapes: shapes, annotations: annotations,
    }, source);
    if (!$("series-plot").dataset.clickable) {
      // a click in the time series moves the time slider there
      $("series-plot").dataset.clickable = "1";
      $("series-plot").on("plotly_click", (ev) => {
        const pt = ev && ev.points && ev.points[0];
        if (!pt || !state.scenario) return;
        const t = state.scenario.t;
        let best = 0;
        for (let i = 1; i < t.length; i++) {
          if (Math.abs(t[i] - pt.x) < Math.abs(t[best] - pt.x)) best = i;
        }
        stopPlay();
        $("time-slider").value = String(best);
        drawScenario(best);
      });
    }
    state.step = k;
    $("time-label").textContent = "t = " + fmt(sc.t[k]) + " s · risk " + fmt(s.r_dep[k]) +
      " · TTC " + fmt(s.ttc[k]) + " s";
  }

  function stopPlay() {
    if (state.timer) {
      clearInterval(state.timer);
      state.timer = null;
    }
    $("play-button").textContent = "▶ Play";
  }

  function togglePlay() {
    if (!state.scenario) return;
    if (state.timer) {
      stopPlay();
      return;
    }
    const slider = $("time-slider");
    if (+slider.value >= +slider.max) slider.value = "0";
    $("play-button").textContent = "❚❚ Pause";
    let drawing = false;
    state.timer = setInterval(async () => {
      if (drawing) return;
      const next = +slider.value + 1;
      if (next > +slider.max) {
        stopPlay();
        return;
      }
      slider.value = String(next);
      drawing = true;
      try { await drawScenario(next); } finally { drawing = false; }
    }, 100);
  }

  // ------------------------------------------------------------------ drawing a sample
  function parseCount(input, min, what) {
    const text = input.value.trim();
    if (!/^\d+$/.test(text) || parseInt(text, 10) < min) {
      input.classList.add("invalid");
      throw new ApiError(0, what + " must be a whole number ≥ " + min + ", got '" + text + "'");
    }
    input.classList.remove("invalid");
    return parseInt(text, 10);
  }

  function splitConstraints(text) {
    return text.replace(/&/g, ";").replace(/,/g, ";").split(";").map((s) => s.trim())
      .filter((s) => s.length > 0);
  }

  async function drawSample(event) {
    event.preventDefault();
    clearError();
    const button = $("draw-button");
    const status = $("draw-status");
    let body;
    try {
      body = {
        model: state.model || "default",
        constraints: splitConstraints($("constraint-input").value),
        n: parseCount($("n-input"), 1, "n"),
        seed: parseCount($("seed-input"), 0, "seed"),
        sampler: $("sampler-select").value,
      };
    } catch (e) {
      showError("draw a new sample: " + e.message);
      return;
    }
    button.disabled = true;
    busy(1);
    try {
      status.textContent = "starting…";
      const created = await api("/catalogues", {
        method: "POST", headers: { "Content-Type": "application/json" },
        body: JSON.stringify(body),
      });
      $("constraint-input").classList.remove("invalid");
      const info = await waitFor(created.id, status);
      status.textContent = "catalogue " + created.id + " " + info.status + " (" +
        info.scenarios_stored + " of " + info.n + " scenarios)";
      // a failed catalogue is shown too: its error and the chunks it stored
      await loadLists();
      await selectCatalogue(created.id, true);
      if (info.status !== "done") {
        throw new ApiError(0, "catalogue " + created.id + " " + info.status +
                              (info.error ? ": " + info.error : ""));
      }
    } catch (e) {
      if (e.field && e.field.indexOf("constraints") >= 0) {
        $("constraint-input").classList.add("invalid");
      }
      if (status.textContent === "starting…") status.textContent = "";
      reportError("draw a new sample", e);
    } finally {
      button.disabled = false;
      busy(-1);
    }
  }

  // what a running catalogue is doing, e.g. "estimating P(A): pilot (plain Monte Carlo)
  // 262,144 / 1,048,576" (the P(A) estimate can take a minute with the progress at 0 %)
  function stageText(stage) {
    const counts = stage.done !== null && stage.total !== null && stage.total > 1 ?
      " " + stage.done.toLocaleString("en") + " / " + stage.total.toLocaleString("en") : "";
    return stage.name + counts;
  }

  // "11 % (33 of 300 scenarios computed, 0 stored)": the percentage counts the scenarios
  // the workers report done, chunks are stored whole (before, the counts were the stored
  // ones only: "running 11 % (0 of 300 scenarios)")
  function progressText(info) {
    const done = info.scenarios_done === undefined ? info.scenarios_stored
      : info.scenarios_done;
    return Math.round(100 * info.progress) + " % (" + done.toLocaleString("en") + " of " +
      info.n.toLocaleString("en") + " scenarios computed" +
      (info.scenarios_stored !== done ? ", " + info.scenarios_stored.toLocaleString("en") +
       " stored" : "") + ")";
  }

  function waitFor(id, status) {
    return new Promise((resolve, reject) => {
      const tick = async () => {
        try {
          const info = await api("/catalogues/" + encodeURIComponent(id));
          status.textContent = "catalogue " + id + ": " + info.status + " " +
            progressText(info) + (info.stage ? " · " + stageText(info.stage) : "");
          if (info.status === "queued" || info.status === "running") {
            setTimeout(tick, 400);
          } else {
            resolve(info);
          }
        } catch (e) {
          reject(e);
        }
      };
      tick();
    });
  }

  function schedulePoll(id) {
    if (state.poll) clearTimeout(state.poll);
    state.poll = setTimeout(() => {
      state.poll = null;
      if (state.catalogue === id) { loadRisk(); loadShift(); }
    }, 1500);
  }

  // ------------------------------------------------------------------ selection
  async function selectCatalogue(id, push) {
    state.catalogue = id || null;
    setSelect($("catalogue-select"), state.catalogue);
    // sections 5 and 6 (dashboard_rates.js) follow the shown catalogue
    window.dispatchEvent(new CustomEvent("scengen:catalogue", { detail: state.catalogue }));
    const cat = state.catalogues.find((c) => c.id === state.catalogue);
    const tasks = [loadShift(), loadRisk()];
    if (cat && cat.model !== state.model) {
      state.model = cat.model;
      setSelect($("model-select"), state.model);
      tasks.push(loadFit());
    }
    if (push) {
      const url = state.catalogue ? "/dashboard/catalogues/" +
        encodeURIComponent(state.catalogue) : "/dashboard";
      setUrl(url, true);
    }
    await Promise.all(tasks);
  }

  // ------------------------------------------------------------------ address bar
  // The page's address names what it shows (/dashboard, /dashboard/catalogues/{id},
  // ?scenario=k); moving between them happens here, without loading the page again.
  let shownUrl = window.location.pathname + window.location.search;

  function setUrl(url, push) {
    if (url === shownUrl) return;
    shownUrl = url;
    if (push) window.history.pushState(null, "", url);
    else window.history.replaceState(null, "", url);
  }

  function route() {
    const m = window.location.pathname.match(/^\/dashboard\/catalogues\/([^/]+)\/?$/);
    const k = new URLSearchParams(window.location.search).get("scenario");
    return { catalogue: m ? decodeURIComponent(m[1]) : null,
             scenario: k !== null && /^\d+$/.test(k) ? parseInt(k, 10) : null };
  }

  async function onPopState() {
    const url = window.location.pathname + window.location.search;
    // a header link (#view-…) only scrolls: the same address, nothing to load (before,
    // every one of them reloaded the whole page)
    if (url === shownUrl) return;
    shownUrl = url;
    clearError();
    const to = route();
    try {
      if (to.catalogue !== state.catalogue) await selectCatalogue(to.catalogue, false);
      if (to.catalogue && to.scenario !== null) await openScenario(to.catalogue, to.scenario);
    } catch (e) {
      reportError("going back", e);
    }
  }

  async function init() {
    keyField();
    exportLinks();
    $("draw-form").addEventListener("submit", drawSample);
    $("play-button").addEventListener("click", togglePlay);
    $("time-slider").addEventListener("input", (e) => {
      stopPlay();
      drawScenario(parseInt(e.target.value, 10));
    });
    $("model-select").addEventListener("change", async (e) => {
      clearError();
      state.model = e.target.value;
      const cat = state.catalogues.find((c) => c.id === state.catalogue);
      const tasks = [loadFit()];
      if (cat && cat.model !== state.model) {
        tasks.push(selectCatalogue(null, true));
      } else if (!state.catalogue) {
        tasks.push(loadShift());
      }
      await Promise.all(tasks);
    });
    $("dataset-select").addEventListener("change", (e) => {
      clearError();
      state.dataset = e.target.value;
      loadFit();
    });
    $("catalogue-select").addEventListener("change", (e) => {
      clearError();
      selectCatalogue(e.target.value, true);
    });
    for (const id of ["constraint-input", "n-input", "seed-input"]) {
      $(id).addEventListener("input", () => $(id).classList.remove("invalid"));
    }
    $("constraint-input").addEventListener("change", () => {
      if (!state.catalogue) loadShift();
    });
    if (initial.error) showError(initial.error);
    busy(1);
    try {
      if (initial.catalogue) {
        const base = "/dashboard/api/catalogues/" + encodeURIComponent(initial.catalogue);
        prefetch(base + "/criticality");
        prefetch(base + "/shift");
      }
      await loadLists();
      const cat = state.catalogues.find((c) => c.id === initial.catalogue);
      const def = state.models.find((m) => m["default"]) || state.models[0];
      state.catalogue = cat ? cat.id : null;
      state.model = cat ? cat.model : def ? def.id : null;
      const model = state.models.find((m) => m.id === state.model);
      state.dataset = model ? model.dataset : (state.datasets[0] || {}).id || null;
      setSelect($("model-select"), state.model);
      setSelect($("dataset-select"), state.dataset);
      setSelect($("catalogue-select"), state.catalogue);
      if (!state.model) showError("no fitted model is available yet (see /health)");
      // the catalogue's own view first (what a test engineer opened the page for), then
      // the constraint shift, then the model views below it
      await loadRisk();
      performance.mark("scengen:catalogue-view");
      await loadShift();
      await loadFit();
      performance.mark("scengen:all-views");
      if (state.catalogue && initial.scenario !== null && initial.scenario !== undefined) {
        await openScenario(state.catalogue, initial.scenario);
      }
    } catch (e) {
      reportError("loading the dashboard", e);
    } finally {
      busy(-1);
      document.body.dataset.ready = "1";
    }
  }

  // A deep link to a section (/dashboard#view-sut): the browser scrolls to it at once,
  // then the views above it grow as their data arrives and push it out of sight. Keep
  // the section at the top while the page settles, until the reader scrolls, clicks or
  // types (or 60 s have passed).
  function holdAnchor() {
    let id = "";
    try {
      id = decodeURIComponent(location.hash.slice(1));
    } catch (e) {
      return; // not percent-encoding (#%E0): names no view, and must not stop the page
    }
    const target = id ? document.getElementById(id) : null;
    if (!target || typeof ResizeObserver === "undefined") return;
    const events = ["wheel", "touchstart", "keydown", "mousedown"];
    const observer = new ResizeObserver(() => target.scrollIntoView({ block: "start" }));
    const release = () => {
      observer.disconnect();
      for (const ev of events) window.removeEventListener(ev, release);
    };
    observer.observe(document.body);
    for (const ev of events) window.addEventListener(ev, release, { passive: true });
    setTimeout(release, 60000);
  }

  window.addEventListener("popstate", onPopState);
  holdAnchor();
  // shared with dashboard_rates.js (sections 5 and 6)
  window.scengen = { api, fmt, esc, table, draw, clearPlot, reportError, centres, COLORS };
  init();
})();
