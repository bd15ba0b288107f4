// annotrace report viewer: hand-written, no framework, no third-party code.
//
// Data: window.ANNOTRACE_INDEX (data/index.js) lists the traces; data/t/NNNNNN.js calls
// annotraceLoaded(payload) when added as a <script> (file:// pages cannot fetch JSON).
// A scene (src/report/scene.rs) is drawn in world coordinates through view = [ox, oy, sx, sy]
// (canvas x = ox + sx*x, y = oy + sy*y). Primitives, in the body frame of an object (or the world,
// for statics): circle {x,y,r,c}, rect {x0,y0,x1,y1,c}, poly {p:[x,y,...],c}, capsule
// {x1,y1,x2,y2,r,c} (a thick segment with round ends), band {r,h,c} (a stripe clipped to the disc),
// line {x1,y1,x2,y2,w,c}, text {s,size,x,y,align,dx,c} (drawn upright); a circle with `clip`
// [x0,y0,x1,y1] is clipped to that box. poses[k][i] = [x, y, angle] or null (absent).
//
// Test hook: index.html#test=N loads trace N of the list, plays it, pauses, clicks an annotation
// and hovers it, then writes what it saw as JSON into <pre id="test-result">.
(function () {
  "use strict";
  var INDEX = window.ANNOTRACE_INDEX || { traces: [], libraries: [], title: "annotrace report" };
  var $ = function (id) { return document.getElementById(id); };
  var canvas = $("scene"), ctx = canvas.getContext("2d");
  var cache = {}, pending = {};
  var st = { p: null, t: 0, k: 0, playing: false, speed: 1, last: 0, timer: null,
             highlight: [], libA: 0, libB: -1, selected: null };

  // ---------- the trace list ----------
  var rows = INDEX.traces;
  var SHOWN = ["trace_id", "env", "success", "n_steps", "annotations"];
  function initList() {
    $("title").textContent = INDEX.title || "annotrace report";
    $("generator").textContent = (INDEX.generator || "") + " · " + rows.length + " traces";
    var envs = {}, labels = {};
    rows.forEach(function (r) { envs[r.env] = 1; r.labels.forEach(function (l) { labels[l] = 1; }); });
    Object.keys(envs).sort().forEach(function (e) { addOption($("f-env"), e, e); });
    Object.keys(labels).sort().forEach(function (l) { addOption($("f-label"), l, l); });
    var head = document.createElement("tr");
    SHOWN.forEach(function (c) { var th = document.createElement("th"); th.textContent = c; head.appendChild(th); });
    $("trace-list").tHead.appendChild(head);
    ["f-env", "f-outcome", "f-label"].forEach(function (id) { $(id).addEventListener("change", renderList); });
    $("f-where").addEventListener("input", renderList);
    renderList();
  }
  function addOption(sel, value, text) {
    var o = document.createElement("option"); o.value = value; o.textContent = text; sel.appendChild(o);
  }
  function renderList() {
    var env = $("f-env").value, out = $("f-outcome").value, label = $("f-label").value;
    var where = null;
    $("f-error").textContent = "";
    try { where = parseWhere($("f-where").value); } catch (e) { $("f-error").textContent = "where: " + e.message; }
    var body = $("trace-list").tBodies[0];
    body.textContent = "";
    var n = 0, LIMIT = 500;
    rows.forEach(function (r) {
      if (env && r.env !== env) return;
      if (out && String(r.success) !== out) return;
      if (label && r.labels.indexOf(label) < 0) return;
      if (where && !where(r)) return;
      n += 1;
      if (n > LIMIT) return;
      var tr = document.createElement("tr");
      tr.className = "trow" + (st.p && st.p.index === r.index ? " current" : "");
      tr.dataset.index = r.index;
      SHOWN.forEach(function (c) { var td = document.createElement("td"); td.textContent = String(r[c]); tr.appendChild(td); });
      tr.addEventListener("click", function () { loadTrace(r.index); });
      body.appendChild(tr);
    });
    $("list-count").textContent = n + " of " + rows.length + " traces" + (n > LIMIT ? " (first " + LIMIT + " shown)" : "");
  }

  // A small WHERE language over the list's columns: comparisons (= != <> < <= > >=), LIKE with % and _,
  // AND, OR, NOT and parentheses; strings in single quotes. `labels = 'x'` means the list holds x.
  function parseWhere(src) {
    var toks = [], re = /\s*(?:(\d+(?:\.\d+)?)|'((?:[^']|'')*)'|(<=|>=|<>|!=|=|<|>|\(|\))|([A-Za-z_][A-Za-z0-9_]*))/y, m;
    src = src.trim();
    if (!src) return null;
    re.lastIndex = 0;
    while (re.lastIndex < src.length) {
      var at = re.lastIndex;
      m = re.exec(src);
      if (!m) throw new Error("cannot read at character " + (at + 1));
      if (m[1] !== undefined) toks.push({ k: "val", v: Number(m[1]) });
      else if (m[2] !== undefined) toks.push({ k: "val", v: m[2].replace(/''/g, "'") });
      else if (m[3] !== undefined) toks.push({ k: "op", v: m[3] });
      else {
        var w = m[4], up = w.toUpperCase();
        if (["AND", "OR", "NOT", "LIKE"].indexOf(up) >= 0) toks.push({ k: "kw", v: up });
        else if (up === "TRUE" || up === "FALSE") toks.push({ k: "val", v: up === "TRUE" });
        else toks.push({ k: "id", v: w });
      }
      if (/^\s*$/.test(src.slice(re.lastIndex))) break;
    }
    var i = 0;
    function peek(k, v) { var t = toks[i]; return t && t.k === k && (v === undefined || t.v === v); }
    function take(k, v) { if (!peek(k, v)) throw new Error("expected " + (v || k) + (toks[i] ? " at " + JSON.stringify(toks[i].v) : " at the end")); return toks[i++]; }
    function or() { var a = and(); while (peek("kw", "OR")) { i++; var b = and(); a = (function (a, b) { return function (r) { return a(r) || b(r); }; })(a, b); } return a; }
    function and() { var a = not(); while (peek("kw", "AND")) { i++; var b = not(); a = (function (a, b) { return function (r) { return a(r) && b(r); }; })(a, b); } return a; }
    function not() { if (peek("kw", "NOT")) { i++; var a = not(); return function (r) { return !a(r); }; } return prim(); }
    function prim() {
      if (peek("op", "(")) { i++; var e = or(); take("op", ")"); return e; }
      var col = take("id").v;
      if (INDEX.columns && INDEX.columns.indexOf(col) < 0) throw new Error("no column " + col + " (columns: " + INDEX.columns.join(", ") + ")");
      if (peek("kw", "LIKE")) {
        i++;
        var pat = String(take("val").v).replace(/[.*+?^${}()|[\]\\]/g, "\\$&").replace(/%/g, ".*").replace(/_/g, ".");
        var rx = new RegExp("^" + pat + "$", "i");
        return function (r) { var v = r[col]; return Array.isArray(v) ? v.some(function (x) { return rx.test(x); }) : rx.test(String(v)); };
      }
      var op = take("op").v, val = take("val").v;
      return function (r) {
        var v = r[col];
        if (Array.isArray(v)) { var has = v.indexOf(val) >= 0; return (op === "=") ? has : (op === "!=" || op === "<>") ? !has : false; }
        switch (op) {
          case "=": return v == val;
          case "!=": case "<>": return v != val;
          case "<": return v < val;
          case "<=": return v <= val;
          case ">": return v > val;
          case ">=": return v >= val;
        }
        return false;
      };
    }
    var f = or();
    if (i < toks.length) throw new Error("unexpected " + JSON.stringify(toks[i].v));
    return f;
  }

  // ---------- loading a trace ----------
  window.annotraceLoaded = function (p) {
    cache[p.index] = p;
    var cb = pending[p.index];
    delete pending[p.index];
    if (cb) cb(p);
  };
  function pad6(n) { var s = String(n); while (s.length < 6) s = "0" + s; return s; }
  function loadTrace(index, done) {
    var show = function (p) { showTrace(p); if (done) done(p); };
    if (cache[index]) { show(cache[index]); return; }
    pending[index] = show;
    var s = document.createElement("script");
    s.src = "data/t/" + pad6(index) + ".js";
    s.onerror = function () { $("trace-title").textContent = "cannot load " + s.src; };
    document.body.appendChild(s);
  }
  function showTrace(p) {
    pause();
    st.p = p; st.t = p.t0; st.k = 0; st.highlight = []; st.selected = null;
    $("trace-title").textContent = p.id + " · " + p.env + " · task " + p.task + " · " +
      (p.success ? "success" : "failure") + " (" + p.status + ")";
    $("scrub").max = String(Math.max(0, p.scene.times.length - 1));
    var libs = p.sections.filter(function (s) { return s.kind === "library"; });
    var a = $("lib-a"), b = $("lib-b");
    a.textContent = ""; b.textContent = "";
    addOption(b, "-1", "(none)");
    libs.forEach(function (s, i) { addOption(a, String(i), s.name); addOption(b, String(i), s.name); });
    st.libA = libs.length ? 0 : -1;
    st.libB = libs.length > 1 ? 1 : -1;
    a.value = String(st.libA); b.value = String(st.libB);
    $("show-text").textContent = p.text;
    $("tokens").textContent = "# tokens: " + p.tokens + " (cl100k-style estimate, see docs/detectors.md)";
    renderTimeline();
    renderList();
    seek(p.t0);
  }

  // ---------- the player ----------
  function frameAt(t) {
    var ts = st.p.scene.times, lo = 0, hi = ts.length - 1;
    if (hi < 0) return 0;
    // The timestep nearest to t (the first on a tie), as `render` picks it.
    while (lo < hi) { var mid = (lo + hi) >> 1; if (ts[mid] < t) lo = mid + 1; else hi = mid; }
    if (lo > 0 && (t - ts[lo - 1]) <= (ts[lo] - t)) return lo - 1;
    return lo;
  }
  function seek(t) {
    if (!st.p) return;
    var p = st.p;
    st.t = Math.min(Math.max(t, p.t0), p.t1);
    st.k = frameAt(st.t);
    $("scrub").value = String(st.k);
    $("clock").textContent = "t = " + st.t.toFixed(2) + " s · step " + st.k + "/" + (p.scene.times.length - 1);
    draw();
    placePlayhead();
  }
  function play() {
    if (!st.p) return;
    if (st.t >= st.p.t1) seek(st.p.t0);
    st.playing = true; st.last = performance.now();
    $("play").textContent = "pause";
    tick();
  }
  function pause() {
    st.playing = false;
    if (st.timer) clearTimeout(st.timer);
    st.timer = null;
    $("play").textContent = "play";
  }
  function tick() {
    if (!st.playing) return;
    var now = performance.now();
    var dt = (now - st.last) / 1000 * st.speed;
    st.last = now;
    seek(st.t + dt);
    if (st.t >= st.p.t1) { pause(); return; }
    st.timer = setTimeout(tick, 33);
  }
  $("play").addEventListener("click", function () { if (st.playing) pause(); else play(); });
  $("scrub").addEventListener("input", function () { pause(); seek(st.p.scene.times[Number($("scrub").value)]); });
  $("speed").addEventListener("change", function () { st.speed = Number($("speed").value); });

  function objectPath(o, pose, v) {
    ctx.setTransform(v[2], 0, 0, v[3], v[0], v[1]);
    ctx.translate(pose[0], pose[1]);
    ctx.rotate(pose[2]);
  }
  function fillPrim(q, scale) {
    ctx.fillStyle = q.c; ctx.strokeStyle = q.c;
    switch (q.k) {
      case "circle":
        ctx.beginPath(); ctx.arc(q.x || 0, q.y || 0, q.r, 0, 2 * Math.PI); ctx.fill(); break;
      case "rect":
        ctx.fillRect(Math.min(q.x0, q.x1), Math.min(q.y0, q.y1), Math.abs(q.x1 - q.x0), Math.abs(q.y1 - q.y0)); break;
      case "poly":
        ctx.beginPath(); ctx.moveTo(q.p[0], q.p[1]);
        for (var i = 2; i < q.p.length; i += 2) ctx.lineTo(q.p[i], q.p[i + 1]);
        ctx.closePath(); ctx.fill(); break;
      case "capsule":
        ctx.lineCap = "round"; ctx.lineWidth = 2 * q.r;
        ctx.beginPath(); ctx.moveTo(q.x1, q.y1); ctx.lineTo(q.x2, q.y2); ctx.stroke(); break;
      case "line":
        ctx.lineCap = "round"; ctx.lineWidth = q.w;
        ctx.beginPath(); ctx.moveTo(q.x1, q.y1); ctx.lineTo(q.x2, q.y2); ctx.stroke(); break;
      case "band":
        ctx.save(); ctx.beginPath(); ctx.arc(0, 0, q.r, 0, 2 * Math.PI); ctx.clip();
        ctx.fillRect(-q.r, -q.h, 2 * q.r, 2 * q.h); ctx.restore(); break;
    }
  }
  // The outline of an object as one path (for hit tests and highlights).
  function tracePrims(prims) {
    ctx.beginPath();
    prims.forEach(function (q) {
      switch (q.k) {
        case "circle": ctx.moveTo((q.x || 0) + q.r, q.y || 0); ctx.arc(q.x || 0, q.y || 0, q.r, 0, 2 * Math.PI); break;
        case "poly": ctx.moveTo(q.p[0], q.p[1]); for (var i = 2; i < q.p.length; i += 2) ctx.lineTo(q.p[i], q.p[i + 1]); ctx.closePath(); break;
        case "capsule":
          var a = Math.atan2(q.y2 - q.y1, q.x2 - q.x1);
          ctx.moveTo(q.x1 + q.r * Math.cos(a + Math.PI / 2), q.y1 + q.r * Math.sin(a + Math.PI / 2));
          ctx.arc(q.x1, q.y1, q.r, a + Math.PI / 2, a + 3 * Math.PI / 2);
          ctx.arc(q.x2, q.y2, q.r, a - Math.PI / 2, a + Math.PI / 2);
          ctx.closePath(); break;
      }
    });
  }
  function toCanvas(v, x, y) { return [v[0] + v[2] * x, v[1] + v[3] * y]; }
  function drawText(s, x, y, size, colour, halo, align) {
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.font = "bold " + size.toFixed(1) + "px sans-serif";
    ctx.textAlign = align || "center"; ctx.textBaseline = "middle";
    if (halo) { ctx.lineWidth = 2.5; ctx.strokeStyle = halo; ctx.lineJoin = "round"; ctx.strokeText(s, x, y); }
    ctx.fillStyle = colour; ctx.fillText(s, x, y);
  }
  function order(sc) {
    var idx = sc.objects.map(function (_, i) { return i; });
    return idx.sort(function (a, b) { return (sc.objects[a].layer - sc.objects[b].layer) || (a - b); });
  }
  function draw() {
    var sc = st.p.scene, v = sc.view, poses = sc.poses[st.k] || [];
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = sc.background; ctx.fillRect(0, 0, canvas.width, canvas.height);
    sc.statics.forEach(function (q) {
      if (q.k === "text") {
        var c = toCanvas(v, q.x, q.y);
        drawText(q.s, c[0] + (q.dx || 0), c[1], q.size, q.c, null, q.align);
        return;
      }
      ctx.setTransform(v[2], 0, 0, v[3], v[0], v[1]);
      if (q.clip) {
        ctx.save(); ctx.beginPath();
        ctx.rect(q.clip[0], q.clip[1], q.clip[2] - q.clip[0], q.clip[3] - q.clip[1]); ctx.clip();
        fillPrim(q); ctx.restore();
      } else fillPrim(q);
    });
    order(sc).forEach(function (i) {
      var o = sc.objects[i], pose = poses[i];
      if (!pose) return;
      objectPath(o, pose, v);
      o.prims.forEach(function (q) { fillPrim(q); });
      if (o.text) {
        var c = toCanvas(v, pose[0], pose[1]);
        drawText(o.text.s, c[0], c[1], o.text.size * 0.8, o.text.c, o.text.halo);
      }
    });
    sc.links.forEach(function (l) {
      var a = poses[l[0]], b = poses[l[1]];
      if (!a || !b) return;
      ctx.setTransform(v[2], 0, 0, v[3], v[0], v[1]);
      fillPrim({ k: "line", x1: a[0], y1: a[1], x2: b[0], y2: b[1], w: l[3], c: l[2] });
    });
    // The objects of the hovered annotation, outlined.
    sc.objects.forEach(function (o, i) {
      if (st.highlight.indexOf(o.id) < 0 || !poses[i]) return;
      objectPath(o, poses[i], v);
      tracePrims(o.prims);
      ctx.setTransform(1, 0, 0, 1, 0, 0);
      ctx.lineWidth = 3; ctx.strokeStyle = "#ff9800"; ctx.stroke();
    });
    ctx.setTransform(1, 0, 0, 1, 0, 0);
  }
  function objectAt(x, y) {
    var sc = st.p.scene, poses = sc.poses[st.k] || [], hit = -1;
    order(sc).forEach(function (i) {
      var o = sc.objects[i];
      if (!poses[i] || !o.prims.length) return;
      objectPath(o, poses[i], sc.view);
      tracePrims(o.prims);
      if (ctx.isPointInPath(x, y)) hit = i;
    });
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    return hit;
  }
  canvas.addEventListener("mousemove", function (e) {
    if (!st.p) return;
    var r = canvas.getBoundingClientRect();
    var i = objectAt((e.clientX - r.left) * canvas.width / r.width, (e.clientY - r.top) * canvas.height / r.height);
    var tip = $("hover-tip");
    if (i < 0) { tip.style.display = "none"; return; }
    var o = st.p.scene.objects[i];
    tip.textContent = "id " + o.id + " · " + o.name;
    tip.style.left = (e.clientX + 12) + "px"; tip.style.top = (e.clientY + 12) + "px";
    tip.style.display = "block";
  });
  canvas.addEventListener("mouseleave", function () { $("hover-tip").style.display = "none"; });

  // ---------- the pattern timeline ----------
  var LABEL_W = 170;
  function frac(t) { var p = st.p, span = p.t1 - p.t0; return span > 0 ? (t - p.t0) / span : 0; }
  function renderTimeline() {
    var p = st.p, box = $("rows");
    box.textContent = "";
    var libs = p.sections.filter(function (s) { return s.kind === "library"; });
    var shown = [];
    if (st.libA >= 0 && libs[st.libA]) shown.push([libs[st.libA], "a", "A: "]);
    if (st.libB >= 0 && libs[st.libB] && st.libB !== st.libA) shown.push([libs[st.libB], "b", "B: "]);
    p.sections.forEach(function (s) { if (s.kind !== "library") shown.push([s, s.kind, ""]); });
    shown.forEach(function (e) {
      var s = e[0], cls = e[1];
      var h = document.createElement("div");
      h.className = "section " + s.kind;
      h.textContent = e[2] + s.name + (s.labels.length ? "" : " (none)");
      box.appendChild(h);
      s.labels.forEach(function (l) {
        var row = document.createElement("div"); row.className = "row";
        var lab = document.createElement("div"); lab.className = "label"; lab.textContent = l.label; lab.title = l.label;
        var tr = document.createElement("div"); tr.className = "track";
        tr.addEventListener("click", function (ev) {
          if (ev.target !== tr) return;
          var r = tr.getBoundingClientRect();
          pause(); seek(p.t0 + (ev.clientX - r.left) / r.width * (p.t1 - p.t0));
        });
        l.items.forEach(function (it) {
          var b = document.createElement("div");
          b.className = "bar" + (cls === "b" ? " b" : cls === "truth" ? " truth" : cls === "events" ? " event" : "");
          b.style.left = (100 * frac(it.t0)) + "%";
          if (cls === "a" || cls === "b") b.style.width = (100 * (frac(it.t1) - frac(it.t0))) + "%";
          b.dataset.t0 = it.t0;
          b.dataset.objects = JSON.stringify(it.objects);
          b.addEventListener("click", function (ev) {
            ev.stopPropagation();
            pause();
            if (st.selected) st.selected.classList.remove("selected");
            st.selected = b; b.classList.add("selected");
            seek(it.t0);
          });
          b.addEventListener("mouseenter", function (ev) {
            b.classList.add("hover");
            st.highlight = it.objects.map(String);
            draw();
            var tip = $("bar-tip");
            tip.textContent = l.label + " · t " + it.t0.toFixed(2) + "–" + it.t1.toFixed(2) + " s" +
              (it.objects.length ? " · objects " + it.objects.join(", ") : "") + (it.info ? "\n" + it.info : "");
            tip.style.left = (ev.clientX + 12) + "px"; tip.style.top = (ev.clientY + 12) + "px";
            tip.style.display = "block";
          });
          b.addEventListener("mouseleave", function () {
            b.classList.remove("hover");
            st.highlight = []; draw();
            $("bar-tip").style.display = "none";
          });
          tr.appendChild(b);
        });
        row.appendChild(lab); row.appendChild(tr); box.appendChild(row);
      });
    });
    placePlayhead();
  }
  function placePlayhead() {
    if (!st.p) return;
    var w = $("timeline").clientWidth - LABEL_W - 1;
    $("playhead").style.left = (LABEL_W + 1 + frac(st.t) * w) + "px";
  }
  $("lib-a").addEventListener("change", function () { st.libA = Number($("lib-a").value); renderTimeline(); });
  $("lib-b").addEventListener("change", function () { st.libB = Number($("lib-b").value); renderTimeline(); });
  window.addEventListener("resize", placePlayhead);

  // ---------- the test hook ----------
  function runTest(n) {
    var out = { trace: null, steps: 0 };
    function finish() {
      var pre = $("test-result");
      pre.textContent = JSON.stringify(out);
      pre.dataset.done = "1";
    }
    loadTrace(n, function (p) {
      out.trace = p.id; out.env = p.env; out.steps = p.scene.times.length;
      out.before = { t: st.t, step: st.k, playhead: parseFloat($("playhead").style.left) };
      $("play").click();
      setTimeout(function () {
        out.playing = st.playing || st.t >= p.t1;
        $("play").click();
        out.after = { t: st.t, step: st.k, playhead: parseFloat($("playhead").style.left) };
        // The annotation (of a library) starting nearest 40 % of the trace, away from the playhead.
        var aim = p.t0 + 0.4 * (p.t1 - p.t0), here = st.t;
        var bars = Array.prototype.slice.call(document.querySelectorAll("#rows .bar:not(.event):not(.truth)"))
          .filter(function (b) { return Math.abs(Number(b.dataset.t0) - here) > 1e-6; });
        bars.sort(function (a, b) { return (Math.abs(Number(a.dataset.t0) - aim) - Math.abs(Number(b.dataset.t0) - aim)) || 0; });
        out.bars = bars.length;
        if (bars.length) {
          var bar = bars[0];
          out.clicked = { t0: Number(bar.dataset.t0), objects: JSON.parse(bar.dataset.objects) };
          bar.click();
          out.seeked = { t: st.t, step: st.k, playhead: parseFloat($("playhead").style.left) };
          bar.dispatchEvent(new MouseEvent("mouseenter", { clientX: 10, clientY: 10 }));
          out.highlight = st.highlight.slice();
          $("bar-tip").style.display = "none";
        }
        out.text_chars = $("show-text").textContent.length;
        out.tokens = p.tokens;
        out.sections = p.sections.map(function (s) { return s.kind + ":" + s.name; });
        finish();
      }, 700);
    });
  }

  initList();
  var m = /#test=(\d+)/.exec(location.hash);
  if (m) runTest(Number(m[1]));
  else if (rows.length) loadTrace(rows[0].index);
})();
