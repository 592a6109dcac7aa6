/* hockle dashboard: jobs, a job's results, sweeps and submission, on the REST API.
 *
 * Plain JavaScript, no build step. Safe by construction: every string from the API or the
 * user enters the page through el() as a text node (textContent) or as an attribute value
 * through setAttribute with a fixed attribute name; no markup is ever parsed from a string.
 * The API key lives in sessionStorage (this tab's session) and travels only in the
 * Authorization header.
 */
(function () {
  "use strict";

  var KEY_STORE = "hockle.apiKey";
  var POLL_MS = 2000;
  var MAX_3D_POINTS = 200;        // grid points of the decimated 3-D slice
  var STATES = ["accepted", "running", "successful", "failed", "dismissed"];
  var ACTIVE = { accepted: true, running: true };
  var API = new URL("../v1/", document.baseURI);
  var CONFIG_URL = new URL("config", document.baseURI);

  var state = { auth: false, key: null, cleanup: null };

  // ------------------------------------------------------------------ DOM helpers (text only)
  /** el("tag.cls", {attr: value}, child...): strings become text nodes, never markup. */
  function el(spec, attrs) {
    var parts = spec.split("."), node = document.createElement(parts[0]);
    if (parts.length > 1) node.className = parts.slice(1).join(" ");
    var start = 1;
    if (attrs && typeof attrs === "object" && !(attrs instanceof Node) && !Array.isArray(attrs)) {
      start = 2;
      Object.keys(attrs).forEach(function (name) {
        var v = attrs[name];
        if (v === null || v === undefined || v === false) return;
        if (/^on/i.test(name)) throw new Error("event handler attributes are not used");
        if (name === "text") node.textContent = String(v);
        else if (name === "dataset") Object.keys(v).forEach(function (k) { node.dataset[k] = String(v[k]); });
        else node.setAttribute(name, v === true ? "" : String(v));
      });
    }
    for (var i = start; i < arguments.length; i++) append(node, arguments[i]);
    return node;
  }
  function append(node, child) {
    if (child === null || child === undefined || child === false) return;
    if (Array.isArray(child)) { child.forEach(function (c) { append(node, c); }); return; }
    node.appendChild(child instanceof Node ? child : document.createTextNode(String(child)));
  }
  /** Replace the children of node by the rest of the arguments (as el() appends them). */
  function fill(node) {
    node.replaceChildren();
    for (var i = 1; i < arguments.length; i++) append(node, arguments[i]);
    return node;
  }
  function $(id) { return document.getElementById(id); }
  function banner(text, kind) {
    var b = $("banner");
    if (!text) { b.hidden = true; b.textContent = ""; return; }
    b.hidden = false; b.className = "banner" + (kind ? " " + kind : ""); b.textContent = text;
  }

  // ------------------------------------------------------------------ formatting
  function fmtTime(iso) {
    if (!iso) return "—";
    var d = new Date(iso);
    if (isNaN(d)) return String(iso);
    return d.toISOString().replace("T", " ").slice(0, 19) + " UTC";
  }
  function fmtDuration(sec) {
    if (sec === null || sec === undefined || !isFinite(sec)) return "—";
    if (sec < 10) return Math.max(0, sec).toFixed(1) + " s";
    sec = Math.round(sec);
    if (sec < 60) return sec + " s";
    if (sec < 3600) return Math.floor(sec / 60) + " min " + (sec % 60) + " s";
    return Math.floor(sec / 3600) + " h " + Math.floor((sec % 3600) / 60) + " min";
  }
  function fmtNum(v, digits) {
    if (v === null || v === undefined || !isFinite(v)) return "—";
    var a = Math.abs(v);
    if (a !== 0 && (a < 1e-3 || a >= 1e5)) return v.toExponential(digits || 3);
    return String(Math.round(v * 1e4) / 1e4);
  }
  var ETA_NOTE = "extrapolated from the pace of the last 30 s (or 20 % of the run) of wall time; " +
    "it cannot foresee a change of pace such as first contact";
  function etaText(job) {
    if (job.state === "accepted") return "queued";
    if (job.state !== "running") return "—";
    return job.eta_seconds === null || job.eta_seconds === undefined ? "estimating" : "≈ " + fmtDuration(job.eta_seconds);
  }
  // A successful job's message: a run's warning (hockle_warning: its writhe crossed the
  // closure of the end tangents with fixed steps; docs/numerics.md § 6), a continuation's
  // account of its branch.
  function successNote(job) {
    if (job.kind === "continuation") return el("p.muted", { id: "job-message", text: job.message });
    return el("p.warning", { id: "job-message", role: "status", text: "Warning: " + job.message });
  }
  /** The mark beside a successful run's state when it carries a warning (in the tooltip). */
  function warningMark(message) {
    return el("span.warning", { title: message, dataset: { warning: "1" }, text: " ⚠ warning" });
  }
  /** The jobs list's kind column: a run, a sweep's member (linked to its sweep) or a continuation. */
  function kindCell(job) {
    if (job.kind === "continuation") return el("td.kind", { dataset: { kind: "continuation" }, text: "continuation" });
    if (job.sweep_id) {
      return el("td.kind", { dataset: { kind: "sweep-member" } },
        el("a", { href: "#/sweep/" + encodeURIComponent(job.sweep_id), title: "sweep " + job.sweep_id, text: "sweep member" }));
    }
    return el("td.kind", { dataset: { kind: "run" }, text: "run" });
  }
  function stateBadge(s) { return el("span.state." + (STATES.indexOf(s) >= 0 ? s : "unknown"), { text: s }); }
  function progressBar(p) {
    var bar = el("span.bar", el("span")), pct = Math.max(0, Math.min(100, Number(p) || 0));
    bar.firstChild.style.width = pct + "%";          // CSSOM, allowed by the CSP
    return el("span", bar, " ", el("span.mono", { text: pct.toFixed(1) + " %" }));
  }

  // ------------------------------------------------------------------ API
  function ApiError(status, problem) {
    this.status = status; this.problem = problem || {};
    this.message = (problem && (problem.detail || problem.title)) || ("HTTP " + status);
  }
  function api(path, opts) {
    opts = opts || {};
    var headers = Object.assign({ Accept: "application/json" }, opts.headers || {});
    if (state.key) headers.Authorization = "Bearer " + state.key;
    return fetch(new URL(path, API), {
      method: opts.method || "GET", headers: headers, body: opts.body, cache: "no-store",
      credentials: "omit", redirect: "error"
    }).then(function (resp) {
      if (resp.status === 304) return { status: 304, etag: resp.headers.get("ETag") };
      if (resp.status === 401 && state.auth) { refused(); }
      var type = resp.headers.get("Content-Type") || "";
      var body = opts.raw && resp.ok ? resp.blob() : (type.indexOf("json") >= 0 ? resp.json() : resp.text());
      return body.then(function (data) {
        if (!resp.ok) throw new ApiError(resp.status, typeof data === "object" ? data : { detail: data });
        return { status: resp.status, data: data, etag: resp.headers.get("ETag"), headers: resp.headers };
      });
    });
  }
  /**
   * Reads of result files one at a time: the API opens NetCDF files in a thread pool, and
   * concurrent reads of one file in one API process have crashed it (netCDF4/HDF5 are not
   * thread-safe), so this page never has two of them in flight.
   */
  var resultChain = Promise.resolve();
  function apiResult(path, opts) {
    var p = resultChain.then(function () { return api(path, opts); });
    resultChain = p.catch(function () { return null; });
    return p;
  }
  function problemNode(err) {
    var p = err.problem || {}, box = el("div.card.error", { role: "alert" },
      el("strong", { text: (p.title || "Error") + " (" + (err.status || "network") + ")" }),
      p.detail ? el("div", { text: p.detail }) : null);
    (p.errors || []).forEach(function (e) { box.appendChild(el("div.mono", { text: (e.loc || "(document)") + ": " + e.msg })); });
    if (!err.status) box.appendChild(el("div", { text: String(err.message || err) }));
    return box;
  }
  /** A poller of one URL: If-None-Match with the last ETag; onData only when it changed. */
  function poller(path, onData, onError) {
    var etag = null, timer = null, stopped = false, last = null;
    function tick() {
      var headers = etag ? { "If-None-Match": etag } : {};
      api(path, { headers: headers }).then(function (r) {
        if (stopped) return;
        if (r.status === 304) { onData(last, true); }
        else { etag = r.etag; last = r.data; onData(r.data, false); }
      }).catch(function (err) { if (!stopped && onError) onError(err); })
        .then(function () { if (!stopped) timer = setTimeout(tick, POLL_MS); });
    }
    tick();
    return function () { stopped = true; clearTimeout(timer); };
  }

  // ------------------------------------------------------------------ key handling
  function refused() {
    sessionStorage.removeItem(KEY_STORE);
    state.key = null;
    showLogin("The service refused the API key (401): it is not one this service knows.");
  }
  function showLogin(message) {
    if (state.cleanup) { state.cleanup(); state.cleanup = null; }
    fill($("main"));
    $("login").hidden = false;
    $("login-message").textContent = message || "";
    $("forget").hidden = true;
    $("who").textContent = "";
    $("key").focus();
  }
  function onLogin(ev) {
    ev.preventDefault();
    var key = $("key").value.trim();
    if (!key) return;
    state.key = key;
    $("login-message").textContent = "checking…";
    api("ui/jobs?page_size=1").then(function () {
      sessionStorage.setItem(KEY_STORE, key);
      $("key").value = "";
      $("login").hidden = true;
      signedIn();
      route();
    }).catch(function (err) {
      state.key = null;
      $("login-message").textContent = err.status === 401
        ? "Refused: the service does not know this key (401)."
        : "Could not check the key: " + err.message;
    });
  }
  function signedIn() {
    $("forget").hidden = !state.auth;
    $("who").textContent = state.auth ? "key set for this session" : "no API keys configured";
  }

  // ------------------------------------------------------------------ router
  function route() {
    if (state.cleanup) { state.cleanup(); state.cleanup = null; }
    if (state.auth && !state.key) { showLogin(""); return; }
    var hash = location.hash.replace(/^#\/?/, ""), parts = hash.split("/"), main = $("main");
    fill(main);
    document.querySelectorAll("[data-nav]").forEach(function (a) {
      a.classList.toggle("active", a.dataset.nav === (parts[0] === "job" ? "jobs" : parts[0] === "sweep" ? "sweeps" : parts[0] || "jobs"));
    });
    var id = decodeURIComponent(parts[1] || "");
    if (parts[0] === "job" && id) state.cleanup = jobPage(main, id);
    else if (parts[0] === "sweep" && id) state.cleanup = sweepPage(main, id);
    else if (parts[0] === "sweeps") state.cleanup = sweepLookup(main);
    else if (parts[0] === "submit") state.cleanup = submitPage(main);
    else state.cleanup = jobsPage(main);
  }

  // ------------------------------------------------------------------ jobs page
  function jobsPage(main) {
    var pageSize = 50, tokens = [null], page = 0, filter = "", stop = null;
    var tbody = el("tbody"), info = el("span.muted", { id: "jobs-updated" });
    var pageLabel = el("span", { id: "jobs-page" }), prev = el("button", { type: "button", text: "‹ Newer" });
    var next = el("button", { type: "button", text: "Older ›" });
    var stateSel = el("select", { "aria-label": "state" }, el("option", { value: "", text: "all states" }),
      STATES.map(function (s) { return el("option", { value: s, text: s }); }));
    var sizeSel = el("select", { "aria-label": "page size" }, [25, 50, 100, 200].map(function (n) {
      return el("option", n === pageSize ? { value: n, text: n + " per page", selected: true } : { value: n, text: n + " per page" });
    }));
    var nextToken = null;
    main.appendChild(el("div.card",
      el("h1", { text: "Jobs" }),
      el("div.toolbar", stateSel, sizeSel, el("span.pager", prev, pageLabel, next), info),
      el("table", { id: "jobs" },
        el("thead", el("tr", ["Name", "Kind", "State", "Progress", "ETA", "Attempts", "Submitted", "Started", "Finished", "Wall", ""].map(function (h, i) {
          return el(i === 5 || i === 9 ? "th.num" : "th", { text: h });
        }))), tbody)));

    function row(job) {
      var actions = el("td");
      if (ACTIVE[job.state]) {
        var b = el("button.danger", { type: "button", text: job.cancel_requested ? "Stopping…" : "Dismiss", dataset: { dismiss: job.id } });
        b.disabled = !!job.cancel_requested;
        b.addEventListener("click", function () { dismissJob(job.id, b); });
        actions.appendChild(b);
      }
      var warned = job.state === "successful" && job.kind !== "continuation" && job.message;
      return el("tr", { dataset: { jobId: job.id, state: job.state } },
        el("td.name", el("a", { href: "#/job/" + encodeURIComponent(job.id), text: job.name || job.id })),
        kindCell(job),
        el("td", stateBadge(job.state), warned ? warningMark(job.message) : null),
        el("td", progressBar(job.progress)),
        el("td", { title: job.state === "running" ? ETA_NOTE : null, text: etaText(job) }),
        el("td.num", { text: job.attempts }),
        el("td", { text: fmtTime(job.created) }),
        el("td", { text: fmtTime(job.started) }),
        el("td", { text: fmtTime(job.finished) }),
        el("td.num", { text: fmtDuration(job.wall_time) }),
        actions);
    }
    function restart() {
      if (stop) stop();
      var q = "ui/jobs?page_size=" + pageSize + (filter ? "&status=" + encodeURIComponent(filter) : "") +
        (tokens[page] ? "&page_token=" + encodeURIComponent(tokens[page]) : "");
      pageLabel.textContent = "page " + (page + 1);
      prev.disabled = page === 0;
      stop = poller(q, function (data, same) {
        info.textContent = "updated " + new Date().toISOString().slice(11, 19) + " UTC" + (same ? " (not modified)" : "");
        if (same) return;
        nextToken = data.next_page_token;
        next.disabled = !nextToken;
        fill(tbody, data.jobs.map(row));
        performance.mark("hockle:jobs-rendered");
        if (!data.jobs.length) tbody.appendChild(el("tr", el("td", { colspan: 11, text: "No jobs." })));
      }, function (err) { info.textContent = "could not refresh: " + err.message; });
    }
    prev.addEventListener("click", function () { if (page > 0) { page--; restart(); } });
    next.addEventListener("click", function () { if (nextToken) { tokens[page + 1] = nextToken; page++; restart(); } });
    stateSel.addEventListener("change", function () { filter = stateSel.value; tokens = [null]; page = 0; restart(); });
    sizeSel.addEventListener("change", function () { pageSize = Number(sizeSel.value); tokens = [null]; page = 0; restart(); });
    restart();
    return function () { if (stop) stop(); };
  }

  function dismissJob(id, button) {
    if (button) button.disabled = true;
    return api("jobs/" + encodeURIComponent(id), { method: "DELETE" }).then(function (r) {
      banner(r.status === 202 ? "Job " + id + " is stopping (within one time step)." : "Job " + id + " dismissed.");
    }).catch(function (err) { banner("Could not dismiss job " + id + ": " + err.message, "error"); if (button) button.disabled = false; });
  }

  // ------------------------------------------------------------------ YAML of a case
  function yamlScalar(v) {
    if (v === null) return "null";
    if (typeof v === "number" || typeof v === "boolean") return String(v);
    var s = String(v);
    return /^[A-Za-z_][\w .\-\/]*$/.test(s) && !/^(true|false|null|yes|no|on|off|~)$/i.test(s) && s.trim() === s ? s : JSON.stringify(s);
  }
  function isScalar(v) { return v === null || typeof v !== "object"; }
  /** Flow style ({a: 1}, [1, 2], [{velocity: 0}]) for small values of scalars, else null. */
  function flow(v) {
    if (isScalar(v)) return yamlScalar(v);
    var parts = [];
    if (Array.isArray(v)) {
      for (var i = 0; i < v.length; i++) { var f = flow(v[i]); if (f === null) return null; parts.push(f); }
      var text = "[" + parts.join(", ") + "]";
    } else {
      var keys = Object.keys(v);
      for (i = 0; i < keys.length; i++) { f = flow(v[keys[i]]); if (f === null) return null; parts.push(yamlScalar(keys[i]) + ": " + f); }
      text = "{" + parts.join(", ") + "}";
    }
    return text.length <= 64 ? text : null;
  }
  function toYaml(v, indent) {
    indent = indent || "";
    var inline = flow(v);
    if (inline !== null) return inline;
    var out = [];
    if (Array.isArray(v)) {
      v.forEach(function (item) {
        var body = flow(item);
        out.push(indent + "- " + (body !== null ? body : toYaml(item, indent + "  ").replace(/^\s+/, "")));
      });
      return out.join("\n");
    }
    Object.keys(v).forEach(function (k) {
      var item = v[k], body = flow(item);
      out.push(indent + yamlScalar(k) + ":" + (body !== null ? " " + body : "\n" + toYaml(item, indent + "  ")));
    });
    return out.join("\n");
  }

  // ------------------------------------------------------------------ plots
  var PLOTS = [
    { id: "energies", title: "Energies and work in (J)", names: ["energy_bending", "energy_torsion", "energy_kinetic", "energy_total", "work_in"] },
    { id: "topology", title: "Twist Tw, writhe Wr, linking number Lk (turns)", names: ["twist", "writhe", "linking_number"] },
    { id: "contacts", title: "Contact pairs", names: ["contact_count"] },
    { id: "gap", title: "Smallest surface gap (m)", names: ["min_surface_gap"] },
    { id: "dt", title: "Step size Δt (s)", names: ["dt"] },
    { id: "newton", title: "Newton iterations", names: ["newton_iterations"] }
  ];
  var COLORS = ["#1f5fa8", "#c0392b", "#27ae60", "#8e44ad", "#d68910", "#17a589"];
  /** Tick labels with the decimals their spacing needs (uPlot's default rounds 1e-4 steps to 0). */
  function ticks(splits) {
    var step = splits.length > 1 ? Math.abs(splits[1] - splits[0]) : Math.abs(splits[0]) || 1;
    var dec = 0;                  // the decimals of the spacing: 2.5 -> 1, 0.002 -> 3
    while (dec < 12 && Math.abs(Math.round(step * Math.pow(10, dec)) - step * Math.pow(10, dec)) > 1e-6 * step * Math.pow(10, dec)) dec++;
    var mag = Math.max.apply(null, splits.map(function (v) { return Math.abs(v || 0); }));
    var sig = Math.min(8, Math.max(1, Math.ceil(Math.log10(mag / step) - 1e-9)));
    return splits.map(function (v) {
      return v === null ? "" : dec > 4 ? v.toExponential(sig) : v.toFixed(dec);
    });
  }
  function makePlot(host, title, time, series, cursor) {
    var names = Object.keys(series);
    var width = Math.max(300, host.clientWidth - 4);
    var opts = {
      width: width, height: 220, title: "",
      scales: { x: { time: false } },
      axes: [{ label: "time (s)" }, { size: 64, values: function (u, splits) { return ticks(splits); } }],
      series: [{ label: "t (s)" }].concat(names.map(function (n, i) {
        return { label: n, stroke: COLORS[i % COLORS.length], width: 1.5, spanGaps: false };
      })),
      hooks: { draw: [function (u) {
        if (cursor.t === null) return;
        var x = u.valToPos(cursor.t, "x", true), ctx = u.ctx;
        ctx.save(); ctx.strokeStyle = "rgba(0,0,0,0.45)"; ctx.setLineDash([4, 4]); ctx.lineWidth = 1;
        ctx.beginPath(); ctx.moveTo(x, u.bbox.top); ctx.lineTo(x, u.bbox.top + u.bbox.height); ctx.stroke(); ctx.restore();
      }] }
    };
    var data = [time].concat(names.map(function (n) { return series[n]; }));
    return new window.uPlot(opts, data, host);
  }

  // ------------------------------------------------------------------ job page
  function jobPage(main, id) {
    var enc = encodeURIComponent(id), stops = [], plots = [], loaded = false, cursor = { t: null };
    var head = el("div.card", { id: "job-head" }, el("p.muted", { text: "loading…" }));
    var caseBox = el("pre.yaml", { id: "case-yaml", text: "loading…" });
    var eventsBox = el("div", { id: "events" }, el("p.muted", { text: "after the run" }));
    var plotsBox = el("div.grid", { id: "plots" });
    var canvas = el("canvas", { id: "rod3d", "aria-label": "the rod in 3-D" });
    var slider = el("input", { id: "time-slider", type: "range", min: 0, max: 0, step: 1, value: 0, "aria-label": "output time" });
    var timeLabel = el("span.mono", { id: "time-label" }), view3dInfo = el("p.muted", { id: "view3d-info" });
    var view3dBox = el("div.view3d", { id: "view3d" }, canvas, el("div.toolbar", el("label", { text: "output time " }), timeLabel), slider, view3dInfo);
    var branch = null;            // a continuation job's page (branchView), once its kind is known
    main.append(head);
    /** The page below the head, by the job's kind: a run's time history, or a branch. */
    function layout(job) {
      if (job.kind === "continuation") {
        branch = branchView(enc, caseBox);
        main.append(branch.node);
        return;
      }
      main.append(
        el("div.two", el("div.card", el("h2", { text: "Case" }), caseBox), el("div.card", el("h2", { text: "Events" }), eventsBox)),
        el("div.card", el("h2", { text: "Rod in 3-D" }), view3dBox),
        el("div.card", el("h2", { text: "Scalar series" }), plotsBox));
    }

    api("jobs/" + enc + "/spec").then(function (r) {
      caseBox.textContent = toYaml(r.data);
      caseBox.dataset.loaded = "1";
      state.caseSpec = r.data;
      head.dataset.case = "1";
    }).catch(function (err) { fill(caseBox, problemNode(err)); });

    function renderHead(job) {
      var buttons = el("div.toolbar");
      if (ACTIVE[job.state]) {
        var b = el("button.danger", { type: "button", id: "dismiss", text: job.cancel_requested ? "Stopping…" : "Dismiss" });
        b.disabled = !!job.cancel_requested;
        b.addEventListener("click", function () { dismissJob(job.id, b); });
        buttons.appendChild(b);
      }
      if (job.result_available) {
        var dl = el("button.primary", { type: "button", id: "download", text: "Download NetCDF" + (job.result_partial ? " (partial)" : "") });
        dl.addEventListener("click", function () { download("jobs/" + enc + "/results", job.id + ".nc", dl); });
        var pv = el("button", { type: "button", id: "download-paraview", text: "Download ParaView (.pvd, zip)" });
        pv.addEventListener("click", function () { download("ui/jobs/" + enc + "/paraview", job.id + "-paraview.zip", pv); });
        buttons.appendChild(dl);
        buttons.appendChild(pv);
      }
      var kv = el("dl.kv",
        el("dt", { text: "state" }), el("dd", stateBadge(job.state)),
        el("dt", { text: "progress" }), el("dd", progressBar(job.progress)),
        el("dt", { text: "ETA" }), el("dd", { title: ETA_NOTE, text: etaText(job) }),
        job.kind === "continuation"
          ? [el("dt", { text: "points" }), el("dd", { text: job.step + " of at most " + job.n_steps }),
             el("dt", { text: "ends read at" }), el("dd", { title: "the time at which the case's end conditions are read (continuation.time, default numerics.t_end)", text: "t = " + fmtNum(job.t_end) + " s" })]
          : [el("dt", { text: "simulated" }), el("dd", { text: fmtNum(job.sim_time) + " of " + fmtNum(job.t_end) + " s, step " + job.step + " of ~" + job.n_steps })],
        el("dt", { text: "grid points" }), el("dd", { text: job.grid_points }),
        el("dt", { text: "attempts" }), el("dd", { text: job.attempts }),
        el("dt", { text: "submitted" }), el("dd", { text: fmtTime(job.created) }),
        el("dt", { text: "started" }), el("dd", { text: fmtTime(job.started) }),
        el("dt", { text: "finished" }), el("dd", { text: fmtTime(job.finished) }),
        el("dt", { text: "wall time" }), el("dd", { text: fmtDuration(job.wall_time) }),
        el("dt", { text: "worker" }), el("dd", { text: job.worker || "—" }),
        el("dt", { text: "id" }), el("dd.mono", { text: job.id }));
      var msg = job.error ? el("p.error", { text: (job.error.reason || "") + ": " + (job.error.message || "") })
        : job.state === "successful" && job.message ? successNote(job) : null;
      fill(head, el("h1", { id: "job-name", text: job.name || job.id }), kv, msg, buttons);
      head.dataset.state = job.state;
    }

    var stopStatus = poller("jobs/" + enc, function (job, same) {
      if (same || !job) return;
      if (!head.dataset.kind) { head.dataset.kind = job.kind || "dynamic"; layout(job); }
      renderHead(job);
      if (ACTIVE[job.state]) return;
      stopStatus();                // finished: its status no longer changes
      if (job.result_available && !loaded) { loaded = true; loadResults(job); }
    }, function (err) { fill(head, problemNode(err)); });
    stops.push(stopStatus);

    function loadResults(job) {
      if (branch) { branch.load(job); return; }
      apiResult("ui/jobs/" + enc + "/events").then(function (r) { renderEvents(r.data.events); })
        .catch(function (err) { fill(eventsBox, problemNode(err)); });
      Promise.all([apiResult("jobs/" + enc + "/summary"), apiResult("jobs/" + enc + "/results/variables")]).then(function (rs) {
        var summary = rs[0].data, vars = {};
        rs[1].data.variables.forEach(function (v) { vars[v.name] = v; });
        var extra = ["dt", "newton_iterations"].filter(function (n) { return vars[n] && vars[n].dims.join() === "time"; });
        return Promise.all(extra.map(function (n) { return apiResult("jobs/" + enc + "/results/variables/" + n); })).then(function (more) {
          var series = {};
          Object.keys(summary.series).forEach(function (n) { series[n] = summary.series[n].values; });
          more.forEach(function (r) { series[r.data.name] = r.data.data; });
          drawPlots(summary.time, series);
          setup3d(summary.time, series, vars);
        });
      }).catch(function (err) { fill(plotsBox, problemNode(err)); });
    }

    function renderEvents(events) {
      var happened = events.filter(function (e) { return e.time !== null; });
      var table = el("table", { id: "events-table" }, el("thead", el("tr", ["event", "t (s)", "Tw", "Wr", "Lk", "E (J)"].map(function (h) { return el("th", { text: h }); }))),
        el("tbody", events.map(function (e) {
          return el("tr", { dataset: { event: e.name } }, el("td", { text: e.label || e.name.replace(/_/g, " ") }),
            el("td.num", { text: e.time === null ? "did not happen" : fmtNum(e.time) }),
            el("td.num", { text: fmtNum(e.twist) }), el("td.num", { text: fmtNum(e.writhe) }),
            el("td.num", { text: fmtNum(e.linking_number) }), el("td.num", { text: fmtNum(e.energy_total) }));
        })));
      fill(eventsBox, table, el("p.muted", { text: happened.length + " of " + events.length + " events happened, listed in the order they happened. Buckling onset: the first output at which a point of the centreline has moved more than the rod's largest diameter across the line through its ends from where it was at the first output (a curved lay's own shape does not count; without stored positions: the writhe changed by 0.05 turns)." }));
    }

    function drawPlots(time, series) {
      fill(plotsBox);
      PLOTS.forEach(function (p) {
        var have = {};
        p.names.forEach(function (n) { if (series[n]) have[n] = series[n]; });
        if (!Object.keys(have).length) return;
        var host = el("div.plot", { dataset: { plot: p.id } }, el("h3", { text: p.title }));
        plotsBox.appendChild(host);
        plots.push(makePlot(host, p.title, time, have, cursor));
      });
      plotsBox.dataset.count = String(plots.length);
      performance.mark("hockle:plots-drawn");
      if (!plots.length) plotsBox.appendChild(el("p.muted", { text: "This result has no scalar series." }));
    }

    function setup3d(time, series, vars) {
      if (!vars.position) { view3dInfo.textContent = "This result has no position field (output.fields)."; return; }
      var view = new window.HockleView3D.RodView(canvas), cache = new Map(), pending = null, sNodes = null;
      var spec = state.caseSpec || {}, rod = spec.rod || {}, contact = spec.contact;
      slider.max = String(time.length - 1);
      slider.value = String(time.length - 1);
      function radiusAt(s) {
        var d = rod.diameter;
        if (typeof d === "number") return d / 2;
        if (d && d.s && d.value) {
          var xs = d.s, ys = d.value;
          if (s <= xs[0]) return ys[0] / 2;
          for (var i = 1; i < xs.length; i++) if (s <= xs[i]) return (ys[i - 1] + (ys[i] - ys[i - 1]) * (s - xs[i - 1]) / (xs[i] - xs[i - 1])) / 2;
          return ys[ys.length - 1] / 2;
        }
        return 0.005;
      }
      function show(index) {
        var t = time[index];
        cursor.t = t;
        plots.forEach(function (u) { u.redraw(false); });
        timeLabel.textContent = "t = " + fmtNum(t) + " s (" + (index + 1) + " of " + time.length + ")";
        var key = String(index), t0 = performance.now();
        var get = cache.has(key) ? Promise.resolve(cache.get(key)) :
          apiResult("jobs/" + enc + "/results/variables/position?time=" + encodeURIComponent(t) + "&s=" + sNodes.map(String).join(",")).then(function (r) {
            var d = r.data, pts = d.data;
            if (d.dims[0] !== "s") pts = pts[0].map(function (_, i) { return pts.map(function (row) { return row[i]; }); });
            cache.set(key, pts);
            return pts;
          });
        pending = index;
        get.then(function (pts) {
          if (pending !== index) return;
          var fetched = performance.now() - t0;
          var radii = sNodes.map(radiusAt), sites = [];
          var count = series.contact_count ? series.contact_count[index] : null;
          if (contact && count) {
            var dmax = 2 * Math.max.apply(null, radii);
            sites = window.HockleView3D.contactSites(pts, sNodes, radii, Math.max(3 * dmax, contact.exclusion || 0), 0.15);
          }
          view.setShape(pts, radii, sites, false);
          canvas.dataset.seabedQuads = String(view.seabedQuads || 0);
          canvas.dataset.frame = String(index);
          performance.mark("hockle:view3d-drawn");
          canvas.dataset.points = String(pts.length);
          canvas.dataset.loadMs = fetched.toFixed(1);
          canvas.dataset.drawMs = view.lastDrawMs.toFixed(1);
          view3dInfo.textContent = pts.length + " of " + vars.s.shape[0] + " grid points shown (a decimated slice of position), " +
            (count === null ? "" : count + " contact pair(s) at this time" + (sites.length ? ", sites estimated from the points shown" : "") + "; ") +
            seabedNote + "drag to turn, wheel to zoom.";
        }).catch(function (err) { fill(view3dInfo, problemNode(err)); });
      }
      var seabedNote = "";
      apiResult("ui/jobs/" + enc + "/seabed").then(function (r) {
        var grid = r.data.seabed;
        canvas.dataset.seabed = grid ? grid.kind : "none";
        if (!grid) return;
        view.setSeabed(grid);
        if (view.points) canvas.dataset.seabedQuads = String(view.seabedQuads || 0);
        seabedNote = "the sea floor (" + (grid.kind === "bathymetry" ? "the bathymetry" : "the plane z = " + fmtNum(grid.z[0][0]) + " m") + ") drawn under the rod; ";
      }).catch(function (err) { canvas.dataset.seabed = "error"; fill(view3dInfo, problemNode(err)); });
      apiResult("jobs/" + enc + "/results/variables/s").then(function (r) {
        var all = r.data.data, n = all.length, m = Math.min(n, MAX_3D_POINTS), idx = [];
        for (var i = 0; i < m; i++) idx.push(Math.round(i * (n - 1) / Math.max(1, m - 1)));
        sNodes = idx.filter(function (v, i) { return i === 0 || v !== idx[i - 1]; }).map(function (i) { return all[i]; });
        var timer = null;
        slider.addEventListener("input", function () {
          clearTimeout(timer);
          var index = Number(slider.value);
          timer = setTimeout(function () { show(index); }, 60);
        });
        show(time.length - 1);
      }).catch(function (err) { fill(view3dInfo, problemNode(err)); });
    }

    return function () {
      stops.forEach(function (s) { s(); });
      plots.forEach(function (u) { u.destroy(); });
    };
  }

  // ------------------------------------------------------------------ a continuation's branch
  var BRANCH_MAX_3D_POINTS = 200;
  var STABLE_COLOR = "#1f5fa8", UNSTABLE_COLOR = "#c0392b", SELECTED_COLOR = "#d68910";

  /** Ticks at 1, 2 or 5 x 10^k covering [lo, hi], about n of them. */
  function niceTicks(lo, hi, n) {
    var span = hi - lo, raw = span / Math.max(1, n), mag = Math.pow(10, Math.floor(Math.log10(raw)));
    var step = [1, 2, 5, 10].map(function (k) { return k * mag; }).filter(function (v) { return v >= raw; })[0] || 10 * mag;
    var out = [];
    for (var v = Math.ceil(lo / step) * step; v <= hi + 1e-9 * step; v += step) out.push(Math.abs(v) < 1e-12 * step ? 0 : v);
    return { values: out, step: step };
  }

  /**
   * A continuation job's page below its head: the bifurcation diagram (the parameter against
   * a chosen measure, stable solid, unstable dashed red, branch points and folds marked; a
   * click picks the nearest point with a stored shape), the shape of the chosen equilibrium in
   * 3-D (a slider over the stored shapes), the branch's events and its mode counts. Everything
   * comes from GET /v1/ui/jobs/{id}/branch (service/branch_view.py) and the position slice
   * of one point at a time.
   */
  function branchView(enc, caseBox) {
    var eventsBox = el("div", { id: "branch-events" }, el("p.muted", { text: "after the continuation" }));
    var measureSel = el("select", { id: "branch-measure", "aria-label": "measure" });
    var diagram = el("canvas", { id: "branch-diagram", "aria-label": "bifurcation diagram" });
    var modesBox = el("p.muted", { id: "branch-modes" });
    var legend = el("div.legend",
      el("span.key.stable", { text: "stable (no unstable mode)" }), el("span.key.unstable", { text: "unstable" }),
      el("span", { text: "● branch point  ○ branch point (a pair of modes)  ▲ fold  ◎ the point shown" }));
    var canvas = el("canvas", { id: "rod3d", "aria-label": "the equilibrium in 3-D" });
    var slider = el("input", { id: "point-slider", type: "range", min: 0, max: 0, step: 1, value: 0, "aria-label": "point of the branch" });
    var pointLabel = el("span.mono", { id: "point-label" }), info = el("p.muted", { id: "view3d-info" });
    var node = el("div",
      el("div.card", { id: "branch" }, el("h2", { text: "Bifurcation diagram" }),
        el("div.toolbar", el("label", { text: "measure " }), measureSel), diagram, legend, modesBox),
      el("div.two",
        el("div.card", el("h2", { text: "Shape at a point" }),
          el("div.view3d", { id: "view3d" }, canvas, el("div.toolbar", el("label", { text: "point " }), pointLabel), slider, info)),
        el("div", el("div.card", el("h2", { text: "Events of the branch" }), eventsBox),
          el("div.card", el("h2", { text: "Case and continuation" }), caseBox))));
    var data = null, selected = null, screen = [], view = null, sNodes = null, cache = new Map(), pending = null;

    function measure(name) {
      if (name === "unstable_modes") return { name: name, label: "unstable modes", units: "count", values: data.unstable_modes };
      return data.measures.filter(function (m) { return m.name === name; })[0];
    }
    function valueAt(values, ev) {          // the measure at an event, interpolated in its step
      var x = data.parameter.values, i = ev.after, j = ev.after + 1;
      while (i >= 0 && values[i] === null) i--;            // the nearest defined values
      while (j < x.length && values[j] === null) j++;
      if (i < 0) return j < x.length ? values[j] : null;
      if (j >= x.length || data.branch[i] !== data.branch[j] || x[i] === x[j]) return values[i];
      return values[i] + (values[j] - values[i]) * (ev.parameter - x[i]) / (x[j] - x[i]);
    }

    function draw() {
      var m = measure(measureSel.value), x = data.parameter.values, y = m.values, modes = data.unstable_modes;
      var dpr = window.devicePixelRatio || 1, w = Math.max(420, diagram.clientWidth || 800), h = 380;
      diagram.width = Math.round(w * dpr); diagram.height = Math.round(h * dpr);
      var ctx = diagram.getContext("2d");
      ctx.setTransform(dpr, 0, 0, dpr, 0, 0); ctx.clearRect(0, 0, w, h);
      var left = 84, right = 18, top = 14, bottom = 50;
      var xs = [], ys = [];
      x.forEach(function (v, i) { if (v !== null && y[i] !== null) { xs.push(v); ys.push(y[i]); } });
      data.events.forEach(function (ev) { var v = valueAt(y, ev); if (ev.parameter !== null && v !== null && v !== undefined) { xs.push(ev.parameter); ys.push(v); } });
      if (!xs.length) { ctx.fillText("no values of this measure", left, top + 20); return; }
      function range(vals) {
        var lo = Math.min.apply(null, vals), hi = Math.max.apply(null, vals);
        if (hi === lo) { var d = Math.abs(lo) * 0.1 || 1; lo -= d; hi += d; }
        var pad = 0.05 * (hi - lo);
        return [lo - pad, hi + pad];
      }
      var rx = range(xs), ry = range(ys);
      function px(v) { return left + (v - rx[0]) / (rx[1] - rx[0]) * (w - left - right); }
      function py(v) { return top + (1 - (v - ry[0]) / (ry[1] - ry[0])) * (h - top - bottom); }
      // grid, ticks and axis labels (with units)
      ctx.font = "12px sans-serif"; ctx.strokeStyle = "#e4e6ea"; ctx.fillStyle = "#1d232b"; ctx.lineWidth = 1;
      var tx = niceTicks(rx[0], rx[1], 7), ty = niceTicks(ry[0], ry[1], 6);
      ctx.textAlign = "center"; ctx.textBaseline = "top";
      tx.values.forEach(function (v) { var X = px(v); ctx.beginPath(); ctx.moveTo(X, top); ctx.lineTo(X, h - bottom); ctx.stroke(); ctx.fillText(fmtNum(v), X, h - bottom + 4); });
      ctx.textAlign = "right"; ctx.textBaseline = "middle";
      ty.values.forEach(function (v) { var Y = py(v); ctx.beginPath(); ctx.moveTo(left, Y); ctx.lineTo(w - right, Y); ctx.stroke(); ctx.fillText(fmtNum(v), left - 6, Y); });
      ctx.strokeStyle = "#8a8f96"; ctx.strokeRect(left, top, w - left - right, h - top - bottom);
      ctx.textAlign = "center"; ctx.textBaseline = "bottom";
      ctx.fillText(data.parameter.label, left + (w - left - right) / 2, h - 4);
      ctx.save(); ctx.translate(14, top + (h - top - bottom) / 2); ctx.rotate(-Math.PI / 2); ctx.textBaseline = "middle";
      ctx.fillText(m.label + " (" + m.units + ")", 0, 0); ctx.restore();
      // the branch: stable solid, unstable dashed red; each part on its own
      var segments = 0;
      // stability of a point: 0 stable, 1 unstable, -1 not computed (stability off: grey)
      function kindOf(i) { return modes[i] < 0 ? -1 : modes[i] === 0 ? 0 : 1; }
      function stroke(x0, y0, x1, y1, kind) {
        ctx.strokeStyle = kind === 1 ? UNSTABLE_COLOR : kind === 0 ? STABLE_COLOR : "#8a8f96"; ctx.lineWidth = 2;
        ctx.setLineDash(kind === 1 ? [6, 4] : []);
        ctx.beginPath(); ctx.moveTo(px(x0), py(y0)); ctx.lineTo(px(x1), py(y1)); ctx.stroke();
        segments++;
      }
      // consecutive points where the measure is defined (a measure of the shape is defined
      // only where the shape is stored), within one part of the branch
      var prev = null;
      for (var i = 0; i < x.length; i++) {
        if (x[i] === null || y[i] === null) continue;
        if (prev !== null && data.branch[prev] === data.branch[i]) {
          var a = kindOf(prev), b = kindOf(i);
          if (a === b) stroke(x[prev], y[prev], x[i], y[i], a);
          else {
            var xm = (x[prev] + x[i]) / 2, ym = (y[prev] + y[i]) / 2;
            stroke(x[prev], y[prev], xm, ym, a); stroke(xm, ym, x[i], y[i], b);
          }
        }
        prev = i;
      }
      data.events.forEach(function (ev) {   // the switched branch leaves from its branch point
        if (!ev.switched_here) return;
        var first = data.branch.indexOf(1), v = valueAt(y, ev);
        if (first >= 0 && y[first] !== null && v !== null && v !== undefined) stroke(ev.parameter, v, x[first], y[first], kindOf(first));
      });
      ctx.setLineDash([]);
      // stored points (clickable), events, the point shown
      screen = [];
      ctx.fillStyle = "#5d6875";
      data.stored.forEach(function (i) {
        if (x[i] === null || y[i] === null) return;
        var X = px(x[i]), Y = py(y[i]);
        screen.push({ i: i, x: X, y: Y });
        ctx.beginPath(); ctx.arc(X, Y, 2.2, 0, 2 * Math.PI); ctx.fill();
      });
      var marks = 0;
      data.events.forEach(function (ev) {
        var v = valueAt(y, ev);
        if (ev.parameter === null || v === null || v === undefined) return;
        var X = px(ev.parameter), Y = py(v);
        ctx.strokeStyle = "#1d232b"; ctx.fillStyle = "#1d232b"; ctx.lineWidth = 1.5;
        ctx.beginPath();
        if (ev.kind === "fold") { ctx.moveTo(X, Y - 7); ctx.lineTo(X + 6, Y + 5); ctx.lineTo(X - 6, Y + 5); ctx.closePath(); ctx.fill(); }
        else { ctx.arc(X, Y, 5.5, 0, 2 * Math.PI); if (ev.simple) ctx.fill(); else { ctx.fillStyle = "#fff"; ctx.fill(); ctx.stroke(); } }
        marks++;
      });
      if (selected !== null && x[selected] !== null && y[selected] !== null) {
        ctx.strokeStyle = SELECTED_COLOR; ctx.lineWidth = 2.5;
        ctx.beginPath(); ctx.arc(px(x[selected]), py(y[selected]), 8, 0, 2 * Math.PI); ctx.stroke();
      }
      diagram.dataset.segments = String(segments);
      diagram.dataset.events = String(marks);
      diagram.dataset.points = String(screen.length);
      diagram.dataset.measure = m.name;
      performance.mark("hockle:diagram-drawn");
    }

    function radiusAt(s) {
      var spec = state.caseSpec || {}, rod = (spec.case || spec).rod || {}, d = rod.diameter;
      if (typeof d === "number") return d / 2;
      if (d && d.s && d.value) {
        var xs = d.s, ys = d.value;
        if (s <= xs[0]) return ys[0] / 2;
        for (var i = 1; i < xs.length; i++) if (s <= xs[i]) return (ys[i - 1] + (ys[i] - ys[i - 1]) * (s - xs[i - 1]) / (xs[i] - xs[i - 1])) / 2;
        return ys[ys.length - 1] / 2;
      }
      return 0.005;
    }

    function select(index) {
      selected = index;
      var k = data.stored.indexOf(index);
      if (k >= 0) slider.value = String(k);
      draw();
      var lam = data.parameter.values[index], n = data.unstable_modes[index], m = measure(measureSel.value);
      pointLabel.textContent = "point " + index + " of " + data.n_points + ": " + data.parameter.path + " = " +
        fmtNum(lam) + " " + data.parameter.unit + ", " + (n === 0 ? "stable (no unstable mode)" : n < 0 ? "stability not computed" : n + " unstable mode" + (n === 1 ? "" : "s"));
      modesBox.textContent = "At point " + index + ": " + m.label + " " + fmtNum(m.values[index]) + " " + m.units + "; " +
        "unstable modes along the branch: " + modeRuns() + ".";
      canvas.dataset.point = String(index);
      var key = String(index);
      var get = cache.has(key) ? Promise.resolve(cache.get(key)) :
        apiResult("jobs/" + enc + "/results/variables/position?point=" + index).then(function (r) {
          var pts = r.data.data;
          if (r.data.dims[0] === "xyz") pts = pts[0].map(function (_, j) { return pts.map(function (row) { return row[j]; }); });
          cache.set(key, pts);
          return pts;
        });
      pending = index;
      get.then(function (pts) {
        if (pending !== index) return;
        var keep = [], n = pts.length, m2 = Math.min(n, BRANCH_MAX_3D_POINTS);
        for (var j = 0; j < m2; j++) keep.push(Math.round(j * (n - 1) / Math.max(1, m2 - 1)));
        keep = keep.filter(function (v, j) { return j === 0 || v !== keep[j - 1]; });
        var shown = keep.map(function (j) { return pts[j]; }), radii = keep.map(function (j) { return radiusAt(sNodes ? sNodes[j] : 0); });
        view.setShape(shown, radii, [], true);
        canvas.dataset.points = String(shown.length);
        canvas.dataset.frame = String(index);
        performance.mark("hockle:view3d-drawn");
        info.textContent = shown.length + " of " + n + " grid points shown; the equilibrium at point " + index +
          " (pick another in the diagram or with the slider); drag to turn, wheel to zoom.";
      }).catch(function (err) { fill(info, problemNode(err)); });
    }

    function modeRuns() {
      var out = [], u = data.unstable_modes, start = 0;
      for (var i = 1; i <= u.length; i++) {
        if (i === u.length || u[i] !== u[start]) {
          out.push((u[start] < 0 ? "not computed" : String(u[start])) + " (point" + (i - 1 > start ? "s " + start + "–" + (i - 1) : " " + start) + ")");
          start = i;
        }
      }
      return out.join(", ");
    }

    function renderEvents() {
      var unit = data.parameter.unit, rows = [];
      rows.push(el("tr", { dataset: { event: "start" } }, el("td", { text: "start" }), el("td.num", { text: fmtNum(data.parameter.start) }),
        el("td.num", { text: "0" }), el("td.num", { text: String(data.unstable_modes[0]) }), el("td", { text: "the case's value" })));
      data.events.forEach(function (ev) {
        rows.push(el("tr", { dataset: { event: ev.kind } }, el("td", { text: ev.label }), el("td.num", { text: fmtNum(ev.parameter) }),
          el("td.num", { text: String(ev.after) + "–" + String(ev.after + 1) }),
          el("td.num", { text: (ev.modes_before === null ? "—" : ev.modes_before) + " → " + (ev.modes_after === null ? "—" : ev.modes_after) }),
          el("td", { text: ev.switched_here ? "the branch switched here" : "" })));
      });
      var last = data.n_points - 1;
      rows.push(el("tr", { dataset: { event: "end" } }, el("td", { text: "end" }), el("td.num", { text: fmtNum(data.parameter.values[last]) }),
        el("td.num", { text: String(last) }), el("td.num", { text: String(data.unstable_modes[last]) }), el("td", { text: data.stopped })));
      fill(eventsBox, el("table", { id: "branch-events-table" },
        el("thead", el("tr", ["event", data.parameter.path + (unit ? " (" + unit + ")" : ""), "point", "unstable modes", ""].map(function (h) { return el("th", { text: h }); }))),
        el("tbody", rows)),
        el("p.muted", { text: data.events.length + " fold(s) and branch point(s) located along " + data.n_points + " points" +
          (data.switched_at !== null ? "; the branch switched after point " + data.switched_at : "") +
          ". A simple branch point or a fold changes the number of unstable modes by one, a pair of modes (a round rod's symmetry) by two." }));
    }

    function load() {
      apiResult("ui/jobs/" + enc + "/branch").then(function (r) {
        data = r.data;
        var varying = data.measures.filter(function (m) { return !m.constant; });
        var first = (varying[0] || data.measures[0]).name;
        fill(measureSel, data.measures.map(function (m) {
          var opts = { value: m.name, text: m.label + " (" + m.units + ")" + (m.constant ? ", the same at every point" : "") };
          if (m.name === first) opts.selected = true;
          return el("option", opts);
        }), el("option", { value: "unstable_modes", text: "unstable modes (count)" }));
        measureSel.addEventListener("change", function () { if (selected !== null) select(selected); else draw(); });
        renderEvents();
        diagram.addEventListener("click", function (ev) {
          var rect = diagram.getBoundingClientRect(), cx = ev.clientX - rect.left, cy = ev.clientY - rect.top, best = null, dist = Infinity;
          screen.forEach(function (p) { var d = Math.hypot(p.x - cx, p.y - cy); if (d < dist) { dist = d; best = p.i; } });
          if (best !== null) select(best);
        });
        view = new window.HockleView3D.RodView(canvas);
        slider.max = String(Math.max(0, data.stored.length - 1));
        var timer = null;
        slider.addEventListener("input", function () {
          clearTimeout(timer);
          var k = Number(slider.value);
          timer = setTimeout(function () { select(data.stored[k]); }, 60);
        });
        if (!data.stored.length) { draw(); info.textContent = "The branch stores no shape (shapes_every)."; return; }
        return apiResult("jobs/" + enc + "/results/variables/s").then(function (rs) {
          sNodes = rs.data.data;
          select(data.stored[data.stored.length - 1]);
        });
      }).catch(function (err) { fill(eventsBox, problemNode(err)); fill(modesBox, problemNode(err)); });
    }

    return { node: node, load: load };
  }

  function download(path, filename, button) {
    if (button) button.disabled = true;
    return api(path, { raw: true }).then(function (r) {
      var url = URL.createObjectURL(r.data), a = el("a", { href: url, download: filename });
      document.body.appendChild(a); a.click(); a.remove();
      setTimeout(function () { URL.revokeObjectURL(url); }, 10000);
    }).catch(function (err) { banner("Download failed: " + err.message, "error"); })
      .then(function () { if (button) button.disabled = false; });
  }

  // ------------------------------------------------------------------ sweeps
  function sweepLookup(main) {
    var input = el("input", { id: "sweep-id", placeholder: "sweep id", size: 40, "aria-label": "sweep id" });
    var form = el("form", el("div.toolbar", input, el("button.primary", { type: "submit", text: "Open" })));
    form.addEventListener("submit", function (ev) {
      ev.preventDefault();
      if (input.value.trim()) location.hash = "#/sweep/" + encodeURIComponent(input.value.trim());
    });
    main.appendChild(el("div.card", el("h1", { text: "Sweeps" }),
      el("p", { text: "Open a sweep by its id (the answer of POST /v1/sweeps, or `hockle sweep ... --url`)." }), form));
    return null;
  }

  function sweepPage(main, id) {
    var enc = encodeURIComponent(id), stop = null, lastCounts = null;
    var head = el("div.card", { id: "sweep-head" }, el("p.muted", { text: "loading…" }));
    var mapBox = el("div.card.heat", { id: "sweep-map" }, el("h2", { text: "Threshold map" }), el("p.muted", { text: "loading…" }));
    var membersBox = el("div.card", { id: "sweep-members" });
    main.append(head, mapBox, membersBox);
    var eventSel = el("select", { id: "map-event", "aria-label": "event" }), mapData = null;
    eventSel.addEventListener("change", function () { if (mapData) drawMap(mapData); });

    function render(sw) {
      var buttons = el("div.toolbar");
      if (sw.state === "accepted" || sw.state === "running") {
        var b = el("button.danger", { type: "button", text: "Dismiss sweep" });
        b.addEventListener("click", function () {
          b.disabled = true;
          api("sweeps/" + enc, { method: "DELETE" }).catch(function (err) { banner("Could not dismiss: " + err.message, "error"); });
        });
        buttons.appendChild(b);
      }
      if (sw.result_available) {
        var dl = el("button.primary", { type: "button", text: "Download combined NetCDF" });
        dl.addEventListener("click", function () { download("sweeps/" + enc + "/results", "sweep-" + sw.id + ".nc", dl); });
        buttons.appendChild(dl);
      }
      fill(head, el("h1", { text: "Sweep " + (sw.name || sw.id) }),
        el("p", stateBadge(sw.state), " ", progressBar(sw.progress), " ",
          el("span.muted", { text: Object.keys(sw.counts).map(function (k) { return sw.counts[k] + " " + k; }).join(", ") + " · " + sw.combine + " over " + sw.parameters.map(function (p) { return p.path; }).join(", ") })),
        buttons);
      head.dataset.state = sw.state;
      var paths = sw.parameters.map(function (p) { return p.path; });
      fill(membersBox, el("h2", { text: "Members (" + sw.members.length + ")" }),
        el("table", { id: "members" }, el("thead", el("tr", [el("th.num", { text: "#" })].concat(paths.map(function (p) { return el("th.mono", { text: p }); }), ["state", "progress", "job"].map(function (h) { return el("th", { text: h }); })))),
          el("tbody", sw.members.map(function (m) {
            return el("tr", { dataset: { state: m.state } }, el("td.num", { text: m.index }),
              paths.map(function (p) { return el("td.mono", { text: JSON.stringify(m.values[p]) }); }),
              el("td", stateBadge(m.state), m.state === "successful" && m.message ? warningMark(m.message) : null),
              el("td", progressBar(m.progress)),
              el("td", el("a.mono", { href: "#/job/" + encodeURIComponent(m.job_id), text: m.job_id.slice(0, 8) })));
          }))));
      var counts = JSON.stringify(sw.counts);
      if (counts !== lastCounts) {
        lastCounts = counts;
        apiResult("ui/sweeps/" + enc + "/map").then(function (r) { mapData = r.data; drawMap(r.data); })
          .catch(function (err) { fill(mapBox, el("h2", { text: "Threshold map" }), problemNode(err)); });
      }
      if (!(sw.state === "accepted" || sw.state === "running") && stop) { stop(); stop = null; }
    }

    function drawMap(map) {
      var names = map.events.length ? map.events : ["buckling_onset"];
      var chosen = eventSel.value || "buckling_onset";
      var labels = map.event_labels || {};
      fill(eventSel, names.map(function (n) {
        var text = labels[n] || n;
        return el("option", n === chosen ? { value: n, text: text, selected: true } : { value: n, text: text });
      }));
      var event = eventSel.value, params = map.parameters;
      var rows, cols, rowLabel, colLabel;
      if (map.combine === "grid" && params.length === 2) {
        rows = params[0].values; cols = params[1].values; rowLabel = params[0].path; colLabel = params[1].path;
      } else if (map.combine === "grid" && params.length === 1) {
        rows = [""]; cols = params[0].values; rowLabel = ""; colLabel = params[0].path;
      } else if (map.combine === "zip") {
        rows = [""]; cols = map.members.map(function (m) { return m.index; }); rowLabel = ""; colLabel = "member";
      } else {
        fill(mapBox, el("h2", { text: "Threshold map" }), el("p.muted", { text: "A map is drawn for one or two parameters; this sweep has " + params.length + ". The members' event times are in the table and in the combined dataset (event_time)." }));
        return;
      }
      var values = map.members.map(function (m) { return m.event_time[event]; });
      var finite = values.filter(function (v) { return v !== null && v !== undefined; });
      var lo = Math.min.apply(null, finite), hi = Math.max.apply(null, finite);
      var cell = Math.max(26, Math.min(70, Math.floor(640 / cols.length))), left = rowLabel ? 110 : 20, top = 20;
      var canvas = el("canvas", { id: "map-canvas", "aria-label": "threshold map" });
      var w = Math.max(left + cols.length * cell + 170, left + 8 * colLabel.length + 20), h = Math.max(top + rows.length * cell + 44, top + 130), dpr = window.devicePixelRatio || 1;
      canvas.width = w * dpr; canvas.height = h * dpr; canvas.style.width = w + "px"; canvas.style.height = h + "px";
      var ctx = canvas.getContext("2d"); ctx.scale(dpr, dpr);
      ctx.font = "12px sans-serif"; ctx.textBaseline = "middle";
      function colour(v) {
        var f = hi > lo ? (v - lo) / (hi - lo) : 0.5;   // dark blue (early) to yellow (late)
        return "rgb(" + Math.round(30 + 220 * f) + "," + Math.round(50 + 170 * f) + "," + Math.round(120 - 80 * f) + ")";
      }
      map.members.forEach(function (m, k) {
        var r = rows.length === 1 ? 0 : Math.floor(k / cols.length), c = rows.length === 1 ? k : k % cols.length;
        var x = left + c * cell, y = top + r * cell, v = m.event_time[event];
        if (v !== null && v !== undefined) {
          ctx.fillStyle = colour(v); ctx.fillRect(x, y, cell - 2, cell - 2);
          ctx.fillStyle = hi > lo && (v - lo) / (hi - lo) > 0.5 ? "#1d232b" : "#fff";
          ctx.fillText(fmtNum(v), x + 3, y + cell / 2);
        }
        else if (m.state === "successful" || m.state === "failed" || m.state === "dismissed") {
          ctx.fillStyle = "#e4e6ea"; ctx.fillRect(x, y, cell - 2, cell - 2);
          ctx.fillStyle = "#777"; ctx.fillText("none", x + 3, y + cell / 2);
        } else { ctx.strokeStyle = "#bbb"; ctx.strokeRect(x + 0.5, y + 0.5, cell - 3, cell - 3); ctx.fillStyle = "#999"; ctx.fillText("…", x + cell / 2 - 4, y + cell / 2); }
      });
      ctx.fillStyle = "#1d232b";
      ctx.textAlign = "center";
      cols.forEach(function (v, c) { ctx.fillText(String(v), left + c * cell + cell / 2, top + rows.length * cell + 10); });
      ctx.textAlign = "left";
      rows.forEach(function (v, r) { ctx.fillText(String(v), 4, top + r * cell + cell / 2); });
      ctx.fillText(colLabel, left, top + rows.length * cell + 32);
      if (rowLabel) { ctx.save(); ctx.translate(10, top - 10); ctx.fillText(rowLabel, 0, 0); ctx.restore(); }
      var bx = left + cols.length * cell + 20;
      if (finite.length) {
        for (var i = 0; i < 100; i++) { ctx.fillStyle = colour(lo + (hi - lo) * (1 - i / 99)); ctx.fillRect(bx, top + i * 1.2, 16, 1.3); }
        ctx.fillStyle = "#1d232b";
        ctx.fillText(fmtNum(hi) + " s", bx + 22, top + 2); ctx.fillText(fmtNum(lo) + " s", bx + 22, top + 119);
      }
      fill(mapBox, el("h2", { text: "Threshold map" }),
        el("div.toolbar", el("label", { text: "event " }), eventSel, el("span.muted", { text: "time of the event per member; grey: it did not happen; outlined: not finished." })),
        canvas);
      mapBox.dataset.members = String(finite.length);
    }

    stop = poller("sweeps/" + enc, function (sw, same) { if (!same && sw) render(sw); },
      function (err) { fill(head, problemNode(err)); });
    return function () { if (stop) stop(); };
  }

  // ------------------------------------------------------------------ submit
  var EXAMPLE = [
    "schema_version: 1",
    "name: twisted rod",
    "rod: {length: 1.0, youngs_modulus: 1.25e7, shear_modulus: 5.0e6, density: 1500.0, diameter: 0.02}",
    "boundary:",
    "  start:",
    "    translation: [{velocity: 0}, {velocity: 0}, {velocity: 0}]",
    "    rotation: [{angular_velocity: 0}, {angular_velocity: 0}, {angular_velocity: 1.0}]",
    "  end:",
    "    translation: [{velocity: 0}, {velocity: 0}, {force: 0}]",
    "    rotation: [{angular_velocity: 0}, {angular_velocity: 0}, {angular_velocity: 0}]",
    "numerics: {n_segments: 8, dt: 0.01, t_end: 0.05}", ""].join("\n");

  /** The 1-based line of the field `loc` (e.g. rod.youngs_modulus, boundary.end.translation[2][0].force) in a YAML or JSON text, or null. */
  function lineOf(text, loc) {
    if (!loc) return null;
    var keys = [], re = /([^.[\]]+)|\[(\d+)\]/g, m;
    while ((m = re.exec(loc))) if (m[1] !== undefined && !/^(body|query)$/.test(m[1])) keys.push(m[1]);
    var lines = text.split("\n"), from = 0, found = null;
    for (var k = 0; k < keys.length; k++) {
      var key = keys[k].replace(/[.*+?^${}()|[\]\\]/g, "\\$&");
      var pat = new RegExp("(^|[{,\\s])\"?" + key + "\"?\\s*:");
      var hit = null;
      for (var i = from; i < lines.length; i++) {
        if (pat.test(lines[i])) { hit = i; break; }
      }
      if (hit === null) break;
      found = hit + 1; from = hit;
    }
    return found;
  }

  function submitPage(main) {
    var area = el("textarea", { id: "case", spellcheck: "false", "aria-label": "case spec (YAML or JSON)", placeholder: "Paste a case spec (YAML or JSON), or upload a file." });
    var file = el("input", { type: "file", id: "case-file", accept: ".yaml,.yml,.json,application/json,application/yaml,text/yaml" });
    var example = el("button", { type: "button", text: "Example" });
    var check = el("button", { type: "button", id: "check", text: "Check" });
    var submit = el("button.primary", { type: "button", id: "submit", text: "Submit" });
    var fresh = el("input", { type: "checkbox", id: "fresh" });
    var result = el("div", { id: "check-result", role: "status" });
    var timer = null, seq = 0;
    main.appendChild(el("div.card", el("h1", { text: "Submit a case" }),
      el("p.muted", { text: "The case is checked by the service as you type (the same validation as POST /v1/jobs, nothing is queued); errors are shown at their field." }),
      el("div.toolbar", file, example, check, submit, el("label", fresh, " run again even if an identical case succeeded")),
      area, result));

    function mediaType() { return /^\s*[{[]/.test(area.value) ? "application/json" : "application/yaml"; }
    function showErrors(err) {
      var p = err.problem || {}, text = area.value, lines = text.split("\n");
      var items = (p.errors && p.errors.length ? p.errors : [{ loc: "", msg: p.detail || err.message }]).map(function (e) {
        var line = lineOf(text, e.loc);
        var item = el("div.fielderr", { dataset: { loc: e.loc || "" } },
          line ? el("span.src", { text: "line " + line + " │ " + lines[line - 1] }) : null,
          el("span.loc", { text: (e.loc || "(document)") + ": " }), el("span.msg", { text: e.msg }));
        if (line) {
          item.addEventListener("click", function () {
            var start = lines.slice(0, line - 1).join("\n").length + (line > 1 ? 1 : 0);
            area.focus(); area.setSelectionRange(start, start + lines[line - 1].length);
          });
        }
        return item;
      });
      fill(result, el("p.error", { text: (p.title || "Error") + " (" + err.status + ")" + (p.detail ? ": " + p.detail : "") }), items);
      result.dataset.state = "invalid";
    }
    function validate() {
      if (!area.value.trim()) { fill(result); delete result.dataset.state; return Promise.resolve(false); }
      var mine = ++seq;
      return api("ui/validate", { method: "POST", body: area.value, headers: { "Content-Type": mediaType() } }).then(function (r) {
        if (mine !== seq) return false;
        fill(result, el("p.ok", { text: "Valid: " + (r.data.name || "(no name)") + ", " + r.data.grid_points + " grid points × " + r.data.n_steps + " steps to t = " + r.data.t_end + " s." }));
        result.dataset.state = "valid";
        return true;
      }).catch(function (err) { if (mine === seq) showErrors(err); return false; });
    }
    area.addEventListener("input", function () { clearTimeout(timer); timer = setTimeout(validate, 500); });
    check.addEventListener("click", validate);
    example.addEventListener("click", function () { area.value = EXAMPLE; validate(); });
    file.addEventListener("change", function () {
      var f = file.files && file.files[0];
      if (!f) return;
      var reader = new FileReader();
      reader.onload = function () { area.value = String(reader.result); validate(); };
      reader.readAsText(f);
    });
    submit.addEventListener("click", function () {
      submit.disabled = true;
      api("jobs" + (fresh.checked ? "?fresh=true" : ""), { method: "POST", body: area.value, headers: { "Content-Type": mediaType() } }).then(function (r) {
        banner(r.data.reused === "identical_case" ? "Answered by the earlier job " + r.data.id + ": an identical case already ran successfully (tick “run again” to run it anew)." :
          r.data.reused ? "Answered by the earlier job " + r.data.id + " (" + r.data.reused + ")." : "Submitted: job " + r.data.id + ".");
        location.hash = "#/job/" + encodeURIComponent(r.data.id);
      }).catch(showErrors).then(function () { submit.disabled = false; });
    });
    return function () { clearTimeout(timer); };
  }

  // ------------------------------------------------------------------ start
  function start() {
    $("login-form").addEventListener("submit", onLogin);
    $("forget").addEventListener("click", function () { sessionStorage.removeItem(KEY_STORE); state.key = null; banner(""); showLogin("Key forgotten."); });
    window.addEventListener("hashchange", function () { banner(""); route(); });
    fetch(CONFIG_URL, { cache: "no-store", credentials: "omit" }).then(function (r) { return r.json(); }).then(function (cfg) {
      state.auth = !!cfg.auth;
      document.body.dataset.auth = state.auth ? "keys" : "none";
      if (!state.auth) {
        banner("This service has no API keys configured: no authentication, every job is everyone's. " +
          "The server log warns \u201cNO AUTHENTICATION\u201d at start-up only when the API binds an address other machines can reach, not on a loopback address such as 127.0.0.1.");
      } else {
        state.key = sessionStorage.getItem(KEY_STORE);
      }
      signedIn();
      route();
    }).catch(function (err) { banner("The service does not answer: " + err.message, "error"); });
  }
  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", start); else start();
})();
