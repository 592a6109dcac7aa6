/* hockle dashboard: the rod in 3-D on a plain 2-D canvas.
 *
 * The centreline (n points, global x, y, z in m) is drawn as a tube of the rod's diameter:
 * rings of SIDES vertices around each point in a parallel-transport frame, joined into
 * quads, projected orthographically after a rotation by the user's drag (yaw about z, then
 * pitch), back faces culled, the rest painted far to near (painter's algorithm) with Lambert
 * shading. Contact sites are red discs sorted with the quads. No WebGL: it draws wherever a
 * canvas does (headless browsers included) and a 200-point tube is ~2,400 quads.
 *
 * A scale bar at the top right gives the length of 1, 2 or 5 x 10^k m at the current zoom.
 *
 * The sea floor, when the case has one, is the grid of GET /v1/ui/jobs/{id}/seabed (its
 * elevation z[i][j] at x[i], y[j]): sand-coloured Lambert-shaded quads, sorted among
 * themselves and painted before the rod when the view looks down on the bottom (after it,
 * translucent, when it looks up from below), so the rod lying on it stays in front.
 */
(function () {
  "use strict";
  var SIDES = 12;

  function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
  function add(a, b) { return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]; }
  function mul(a, k) { return [a[0] * k, a[1] * k, a[2] * k]; }
  function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
  function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
  function norm(a) { return Math.sqrt(dot(a, a)); }
  function unit(a) { var n = norm(a); return n > 0 ? mul(a, 1 / n) : [0, 0, 1]; }

  /** Tangents at the points (central differences) and a parallel-transport normal. */
  function frames(points) {
    var n = points.length, t = [], nrm = [], bin = [];
    for (var i = 0; i < n; i++) {
      var a = points[Math.max(0, i - 1)], b = points[Math.min(n - 1, i + 1)];
      t.push(unit(sub(b, a)));
    }
    var first = t[0], ref = Math.abs(first[2]) < 0.9 ? [0, 0, 1] : [1, 0, 0];
    var u = unit(cross(first, ref));
    for (i = 0; i < n; i++) {
      u = unit(sub(u, mul(t[i], dot(u, t[i]))));  // transport: drop the tangent part
      nrm.push(u);
      bin.push(cross(t[i], u));
    }
    return { t: t, n: nrm, b: bin };
  }

  /** Closest points of segments p0-p1 and q0-q1: [distance, midpoint, s, u]. */
  function segmentDistance(p0, p1, q0, q1) {
    var d1 = sub(p1, p0), d2 = sub(q1, q0), r = sub(p0, q0);
    var a = dot(d1, d1), e = dot(d2, d2), f = dot(d2, r), s, u;
    var c = dot(d1, r), b = dot(d1, d2), den = a * e - b * b;
    s = den > 1e-300 ? Math.min(1, Math.max(0, (b * f - c * e) / den)) : 0;
    u = e > 0 ? (b * s + f) / e : 0;
    if (u < 0) { u = 0; s = a > 0 ? Math.min(1, Math.max(0, -c / a)) : 0; }
    else if (u > 1) { u = 1; s = a > 0 ? Math.min(1, Math.max(0, (b - c) / a)) : 0; }
    var cp = add(p0, mul(d1, s)), cq = add(q0, mul(d2, u));
    return [norm(sub(cp, cq)), mul(add(cp, cq), 0.5)];
  }

  /**
   * Contact sites of a polyline: midpoints of segment pairs whose centrelines come closer
   * than (1 + tol) x the sum of the radii, for pairs further apart along s than `minSep`
   * (m). O(n^2) in the points shown (200 points: 20,000 pairs, < 1 ms).
   */
  function contactSites(points, s, radii, minSep, tol) {
    var sites = [], n = points.length;
    for (var i = 0; i + 1 < n; i++) {
      for (var j = i + 2; j + 1 < n; j++) {
        if (s[j] - s[i + 1] < minSep) continue;
        var ri = Math.max(radii[i], radii[i + 1]), rj = Math.max(radii[j], radii[j + 1]);
        var res = segmentDistance(points[i], points[i + 1], points[j], points[j + 1]);
        if (res[0] < (ri + rj) * (1 + tol)) sites.push({ at: res[1], gap: res[0] - ri - rj, r: Math.max(ri, rj) });
      }
    }
    return sites;
  }

  function RodView(canvas) {
    this.canvas = canvas;
    this.yaw = -0.6; this.pitch = 0.35; this.zoom = 1;
    this.points = null; this.radii = null; this.sites = []; this.seabed = null;
    this.center = [0, 0, 0]; this.extent = 1;
    this.lastDrawMs = 0;
    var self = this, drag = null;
    canvas.addEventListener("pointerdown", function (ev) {
      drag = { x: ev.clientX, y: ev.clientY, yaw: self.yaw, pitch: self.pitch };
      canvas.setPointerCapture(ev.pointerId);
    });
    canvas.addEventListener("pointermove", function (ev) {
      if (!drag) return;
      self.yaw = drag.yaw + (ev.clientX - drag.x) * 0.01;
      self.pitch = Math.max(-1.55, Math.min(1.55, drag.pitch + (ev.clientY - drag.y) * 0.01));
      self.draw();
    });
    canvas.addEventListener("pointerup", function () { drag = null; });
    canvas.addEventListener("wheel", function (ev) {
      ev.preventDefault();
      self.zoom = Math.max(0.2, Math.min(50, self.zoom * Math.exp(-ev.deltaY * 0.001)));
      self.draw();
    }, { passive: false });
  }

  /** Set the shape: points (n x 3, m), radii (n, m), contact sites; `fit` recentres. */
  RodView.prototype.setShape = function (points, radii, sites, fit) {
    this.points = points; this.radii = radii; this.sites = sites || [];
    if (fit || !this.fitted) { this.fit(); }
    this.draw();
  };

  /** Set the sea floor: {x: (nx), y: (ny), z: (nx x ny)} in m, or null for none. */
  RodView.prototype.setSeabed = function (grid) {
    this.seabed = grid && grid.x && grid.x.length > 1 && grid.y.length > 1 ? grid : null;
    this.draw();
  };

  /** The sea floor's quads in view coordinates, far to near: [{quad, shade}]. */
  function seabedQuads(grid, view, viewDir, light) {
    var out = [], x = grid.x, y = grid.y, z = grid.z;
    for (var i = 0; i + 1 < x.length; i++) {
      for (var j = 0; j + 1 < y.length; j++) {
        var c = [[x[i], y[j], z[i][j]], [x[i + 1], y[j], z[i + 1][j]],
                 [x[i + 1], y[j + 1], z[i + 1][j + 1]], [x[i], y[j + 1], z[i][j + 1]]];
        var nm = unit(cross(sub(c[2], c[0]), sub(c[3], c[1])));      // upward normal
        var q = c.map(view), vn = viewDir(nm);
        var shade = 0.35 + 0.65 * Math.abs(dot(vn, light));
        out.push({ z: (q[0][2] + q[1][2] + q[2][2] + q[3][2]) / 4, quad: q, shade: shade });
      }
    }
    out.sort(function (u, v) { return u.z - v.z; });
    return out;
  }

  RodView.prototype.fit = function () {
    var p = this.points; if (!p || !p.length) return;
    var lo = p[0].slice(), hi = p[0].slice();
    for (var i = 1; i < p.length; i++) for (var k = 0; k < 3; k++) {
      lo[k] = Math.min(lo[k], p[i][k]); hi[k] = Math.max(hi[k], p[i][k]);
    }
    this.center = mul(add(lo, hi), 0.5);
    this.extent = Math.max(norm(sub(hi, lo)), 4 * Math.max.apply(null, this.radii), 1e-9);
    this.fitted = true;
    this.scaleBase = null;        // set by the next draw from the shape as it is seen
  };

  RodView.prototype.draw = function () {
    var t0 = performance.now();
    var canvas = this.canvas, dpr = window.devicePixelRatio || 1;
    var w = canvas.clientWidth || 600, h = canvas.clientHeight || 400;
    if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
      canvas.width = Math.round(w * dpr); canvas.height = Math.round(h * dpr);
    }
    var ctx = canvas.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, w, h);
    if (!this.points || this.points.length < 2) return;
    var cy = Math.cos(this.yaw), sy = Math.sin(this.yaw), cp = Math.cos(this.pitch), sp = Math.sin(this.pitch);
    var c = this.center, scale;
    // view coordinates: x right, y up, z towards the viewer; world z is up
    function view(v) {
      var x = v[0] - c[0], y = v[1] - c[1], z = v[2] - c[2];
      var x1 = cy * x - sy * y, y1 = sy * x + cy * y;           // yaw about world z
      return [x1, cp * z - sp * y1, sp * z + cp * y1];          // pitch about view x
    }
    function viewDir(v) {
      var x1 = cy * v[0] - sy * v[1], y1 = sy * v[0] + cy * v[1];
      return [x1, cp * v[2] - sp * y1, sp * v[2] + cp * y1];
    }
    var p = this.points, r = this.radii, n = p.length, f = frames(p);
    if (!this.scaleBase) {        // fit: the projected shape fills 90 % of the canvas
      var mx = 1e-12, my = 1e-12, rmax = Math.max.apply(null, r);
      for (var j = 0; j < n; j++) {
        var vj = view(p[j]);
        mx = Math.max(mx, Math.abs(vj[0]) + rmax); my = Math.max(my, Math.abs(vj[1]) + rmax);
      }
      this.scaleBase = 0.45 * Math.min(w / mx, h / my);
    }
    scale = this.scaleBase * this.zoom;
    var rings = [], normals = [];
    for (var i = 0; i < n; i++) {
      var ring = [], nr = [];
      for (var k = 0; k < SIDES; k++) {
        var a = 2 * Math.PI * k / SIDES, dir = add(mul(f.n[i], Math.cos(a)), mul(f.b[i], Math.sin(a)));
        ring.push(view(add(p[i], mul(dir, r[i]))));
        nr.push(viewDir(dir));
      }
      rings.push(ring); normals.push(nr);
    }
    var items = [], light = unit([-0.4, 0.6, 0.7]);
    for (i = 0; i + 1 < n; i++) {
      for (k = 0; k < SIDES; k++) {
        var k2 = (k + 1) % SIDES;
        var nz = normals[i][k][2] + normals[i][k2][2] + normals[i + 1][k][2] + normals[i + 1][k2][2];
        if (nz < -0.2) continue;                                // back face
        var q = [rings[i][k], rings[i][k2], rings[i + 1][k2], rings[i + 1][k]];
        var nm = unit(add(add(normals[i][k], normals[i][k2]), add(normals[i + 1][k], normals[i + 1][k2])));
        var depth = (q[0][2] + q[1][2] + q[2][2] + q[3][2]) / 4;
        var shade = 0.3 + 0.7 * Math.max(0, dot(nm, light));
        items.push({ z: depth, quad: q, shade: shade });
      }
    }
    for (i = 0; i < this.sites.length; i++) {
      var sv = view(this.sites[i].at);
      items.push({ z: sv[2] + this.sites[i].r * 1.05, site: sv, r: this.sites[i].r });
    }
    items.sort(function (u, v) { return u.z - v.z; });
    var ox = w / 2, oy = h / 2;
    ctx.lineJoin = "round";
    var bottom = this.seabed ? seabedQuads(this.seabed, view, viewDir, light) : [];
    var fromAbove = sp >= 0;                      // world up points towards the viewer
    function paintBottom(alpha) {
      for (var m = 0; m < bottom.length; m++) {
        var bq = bottom[m].quad, sh = bottom[m].shade;
        ctx.fillStyle = "rgba(" + Math.round(120 + 90 * sh) + "," + Math.round(100 + 75 * sh) + "," +
          Math.round(60 + 50 * sh) + "," + alpha + ")";
        ctx.strokeStyle = "rgba(120, 95, 60, " + (0.5 * alpha) + ")";
        ctx.lineWidth = 0.5;
        ctx.beginPath();
        ctx.moveTo(ox + bq[0][0] * scale, oy - bq[0][1] * scale);
        for (var e = 1; e < 4; e++) ctx.lineTo(ox + bq[e][0] * scale, oy - bq[e][1] * scale);
        ctx.closePath(); ctx.fill(); ctx.stroke();
      }
    }
    if (fromAbove) paintBottom(1);
    for (i = 0; i < items.length; i++) {
      var it = items[i];
      if (it.quad) {
        var g = Math.round(60 + 160 * it.shade), b2 = Math.round(110 + 140 * it.shade);
        ctx.fillStyle = "rgb(" + Math.round(30 + 60 * it.shade) + "," + g + "," + b2 + ")";
        ctx.strokeStyle = ctx.fillStyle;
        ctx.lineWidth = 0.6;
        ctx.beginPath();
        ctx.moveTo(ox + it.quad[0][0] * scale, oy - it.quad[0][1] * scale);
        for (k = 1; k < 4; k++) ctx.lineTo(ox + it.quad[k][0] * scale, oy - it.quad[k][1] * scale);
        ctx.closePath(); ctx.fill(); ctx.stroke();
      } else {
        ctx.fillStyle = "rgba(200, 30, 30, 0.9)";
        ctx.beginPath();
        ctx.arc(ox + it.site[0] * scale, oy - it.site[1] * scale, Math.max(2, it.r * scale * 0.6), 0, 2 * Math.PI);
        ctx.fill();
      }
    }
    if (!fromAbove) paintBottom(0.45);
    this.seabedQuads = bottom.length;
    // the s = 0 end, and an axis triad
    var s0 = view(p[0]);
    ctx.fillStyle = "#1d232b"; ctx.font = "12px sans-serif";
    ctx.fillText("s = 0", ox + s0[0] * scale + 8, oy - s0[1] * scale);
    var axes = [[1, 0, 0, "x", "#c0392b"], [0, 1, 0, "y", "#27ae60"], [0, 0, 1, "z", "#2c6cb0"]];
    for (k = 0; k < 3; k++) {
      var d = viewDir(axes[k]);
      ctx.strokeStyle = axes[k][4]; ctx.lineWidth = 2;
      ctx.beginPath(); ctx.moveTo(40, h - 40); ctx.lineTo(40 + d[0] * 26, h - 40 - d[1] * 26); ctx.stroke();
      ctx.fillStyle = axes[k][4]; ctx.fillText(axes[k][3], 42 + d[0] * 32, h - 38 - d[1] * 32);
    }
    this.scaleBar = drawScaleBar(ctx, w, h, scale);
    canvas.dataset.scaleBar = this.scaleBar;
    this.lastDrawMs = performance.now() - t0;
  };

  /** A length scale at the top right: a bar of 1, 2 or 5 x 10^k m, 60 to 150 px long at
   * this zoom (the view is orthographic, so it holds anywhere in the picture); its label. */
  function drawScaleBar(ctx, w, h, scale) {
    var target = 100 / scale, mag = Math.pow(10, Math.floor(Math.log10(target)));
    var length = [1, 2, 5, 10].map(function (k) { return k * mag; }).filter(function (v) { return v * scale >= 60; })[0] || 10 * mag;
    var label = length >= 1 ? +length.toPrecision(3) + " m" : length >= 1e-3 ? +(length * 1e3).toPrecision(3) + " mm" : +(length * 1e6).toPrecision(3) + " µm";
    var px = length * scale, x1 = w - 24, x0 = x1 - px, y = 26;          // top right
    ctx.save();
    ctx.strokeStyle = "#1d232b"; ctx.fillStyle = "#1d232b"; ctx.lineWidth = 2; ctx.setLineDash([]);
    ctx.beginPath(); ctx.moveTo(x0, y - 5); ctx.lineTo(x0, y); ctx.lineTo(x1, y); ctx.lineTo(x1, y - 5); ctx.stroke();
    ctx.font = "12px sans-serif"; ctx.textAlign = "center"; ctx.textBaseline = "top";
    ctx.fillText(label, (x0 + x1) / 2, y + 4);
    ctx.restore();
    return label;
  }

  window.HockleView3D = { RodView: RodView, contactSites: contactSites, frames: frames };
})();
