// annotrace survey page: hand-written, no framework, no third-party code.
//
// data/survey.js sets window.ANNOTRACE_SURVEY: the survey's id, seed (a decimal string: it may not fit
// a double), conditions, items (trace, environment, animation, one summary per condition) and texts.
// A participant id (typed, or #p=ID in the URL) picks the order of the items and the condition of each
// through `assignment`, the same seeded shuffle as annotrace's `survey::assignment` (src/survey/assign.rs):
// FNV-1a 64 of the id, SplitMix64 seeded with splitmix64(seed) XOR that key, a Fisher–Yates shuffle,
// then one draw for the condition offset. Ratings are kept in localStorage under
// "annotrace-survey:<id>:<participant>" and exported as CSV (the columns of `columns`).
//
// Test hook: #test=1&p=ID clears that participant's answers, restarts the first animation and decodes
// it with the browser's ImageDecoder (frame count; first and last frames differ), rates every item (position k gets 1 + (k mod 7)),
// reads the CSV the download button would save, goes back to the first item and writes what it saw
// as JSON into <pre id="test-result">.
(function () {
  "use strict";
  var S = window.ANNOTRACE_SURVEY;
  function $(id) { return document.getElementById(id); }

  // ---------- the seeded shuffle (must equal src/survey/assign.rs) ----------
  var MASK = (1n << 64n) - 1n, GOLDEN = 0x9E3779B97F4A7C15n;
  function finalize(z) {
    z = ((z ^ (z >> 30n)) * 0xBF58476D1CE4E5B9n) & MASK;
    z = ((z ^ (z >> 27n)) * 0x94D049BB133111EBn) & MASK;
    return z ^ (z >> 31n);
  }
  function splitmix64(x) { return finalize((x + GOLDEN) & MASK); }
  function fnv1a64(s) {
    var h = 0xcbf29ce484222325n, b = new TextEncoder().encode(s);
    for (var i = 0; i < b.length; i++) h = ((h ^ BigInt(b[i])) * 0x100000001b3n) & MASK;
    return h;
  }
  function Rng(seed) { this.s = seed; }
  Rng.prototype.next = function () { this.s = (this.s + GOLDEN) & MASK; return finalize(this.s); };
  Rng.prototype.below = function (n) {
    var u = Number(this.next() >> 11n) / 9007199254740992;
    return Math.floor(u * n) % Math.max(n, 1);
  };
  function assignment(seed, participant, items, conditions) {
    var rng = new Rng(splitmix64(BigInt(seed)) ^ fnv1a64(participant));
    var order = [];
    for (var i = 0; i < items; i++) order.push(i);
    for (i = items - 1; i >= 1; i--) {
      var j = rng.below(i + 1), t = order[i];
      order[i] = order[j]; order[j] = t;
    }
    var offset = rng.below(conditions);
    return order.map(function (item) { return { item: item, condition: (item + offset) % Math.max(conditions, 1) }; });
  }
  var ID_RE = /^[A-Za-z0-9_.\-]{1,64}$/;

  // ---------- state ----------
  var st = { participant: null, order: [], pos: 0, answers: {} };
  function key() { return "annotrace-survey:" + S.id + ":" + st.participant; }
  function load() {
    try { st.answers = JSON.parse(localStorage.getItem(key()) || "{}") || {}; } catch (e) { st.answers = {}; }
  }
  function save() {
    try { localStorage.setItem(key(), JSON.stringify(st.answers)); } catch (e) { /* private mode: answers live until the tab closes */ }
  }
  function hashParams() {
    var out = {};
    location.hash.replace(/^#/, "").split("&").forEach(function (kv) {
      var i = kv.indexOf("=");
      if (i > 0) out[decodeURIComponent(kv.slice(0, i))] = decodeURIComponent(kv.slice(i + 1));
    });
    return out;
  }

  // ---------- the CSV ----------
  function csvField(v) {
    v = String(v);
    return /[",\n\r]/.test(v) ? '"' + v.replace(/"/g, '""') + '"' : v;
  }
  function csvText() {
    var lines = [S.columns.join(",")];
    st.order.forEach(function (sh, k) {
      var a = st.answers[k + 1];
      if (!a) return;
      var item = S.items[sh.item];
      var row = { survey: S.id, participant: st.participant, seed: S.seed, position: k + 1,
        trace_id: item.trace_id, env: item.env, condition: S.conditions[sh.condition],
        rating: a.rating, answered_at: a.at };
      lines.push(S.columns.map(function (c) { return csvField(row[c]); }).join(","));
    });
    return lines.join("\n") + "\n";
  }
  function download() {
    var blob = new Blob([csvText()], { type: "text/csv" });
    var a = document.createElement("a");
    a.href = URL.createObjectURL(blob);
    a.download = "survey-" + S.id + "-" + st.participant + ".csv";
    document.body.appendChild(a);
    a.click();
    setTimeout(function () { URL.revokeObjectURL(a.href); a.remove(); }, 0);
  }

  // ---------- the page ----------
  function answeredCount() { return Object.keys(st.answers).length; }
  function showStart() {
    $("start").hidden = false;
    $("item").hidden = true;
    var links = $("links");
    if (S.participants.length) {
      links.appendChild(document.createTextNode("or open: "));
      S.participants.forEach(function (p) {
        var a = document.createElement("a");
        a.href = "#p=" + encodeURIComponent(p);
        a.textContent = p;
        a.addEventListener("click", function () { setTimeout(function () { location.reload(); }, 0); });
        links.appendChild(a);
      });
    }
  }
  function begin(participant) {
    st.participant = participant;
    st.order = assignment(S.seed, participant, S.items.length, S.conditions.length);
    load();
    $("start").hidden = true;
    $("who").textContent = "participant " + participant;
    $("export").hidden = false;
    // Continue at the first unanswered item.
    st.pos = 0;
    while (st.pos < st.order.length - 1 && st.answers[st.pos + 1]) st.pos++;
    show();
  }
  function buildScale() {
    var sc = $("scale");
    sc.innerHTML = "";
    var low = document.createElement("span");
    low.className = "anchor"; low.textContent = S.scale.low;
    sc.appendChild(low);
    for (var v = S.scale.min; v <= S.scale.max; v++) {
      var l = document.createElement("label");
      var r = document.createElement("input");
      r.type = "radio"; r.name = "rating"; r.value = String(v); r.id = "rating-" + v;
      r.addEventListener("change", rate);
      l.appendChild(r);
      l.appendChild(document.createTextNode(String(v)));
      sc.appendChild(l);
    }
    var high = document.createElement("span");
    high.className = "anchor"; high.textContent = S.scale.high;
    sc.appendChild(high);
  }
  function rate(e) {
    st.answers[st.pos + 1] = { rating: Number(e.target.value), at: new Date().toISOString() };
    save();
    updateCounts();
  }
  function updateCounts() {
    $("answered").textContent = answeredCount() + " of " + st.order.length + " rated";
    $("done").hidden = answeredCount() < st.order.length;
  }
  function show() {
    var sh = st.order[st.pos], item = S.items[sh.item];
    $("item").hidden = false;
    $("progress").textContent = "item " + (st.pos + 1) + " of " + st.order.length;
    $("video").src = item.video;
    $("guide").textContent = item.guide;
    $("summary").textContent = item.summaries[sh.condition];
    $("question").textContent = S.question;
    var a = st.answers[st.pos + 1];
    document.querySelectorAll("#scale input").forEach(function (r) { r.checked = !!a && Number(r.value) === a.rating; });
    $("prev").disabled = st.pos === 0;
    $("next").disabled = st.pos === st.order.length - 1;
    updateCounts();
  }
  function replay() {
    // Setting the source again restarts an animated image from its first frame.
    var src = S.items[st.order[st.pos].item].video;
    $("video").src = "";
    $("video").src = src;
  }
  $("prev").addEventListener("click", function () { if (st.pos > 0) { st.pos--; show(); } });
  $("next").addEventListener("click", function () { if (st.pos < st.order.length - 1) { st.pos++; show(); } });
  $("replay").addEventListener("click", replay);
  $("export").addEventListener("click", download);
  $("start-form").addEventListener("submit", function (e) {
    e.preventDefault();
    var id = $("participant").value.trim();
    if (!ID_RE.test(id)) {
      $("start-error").textContent = "an id is 1–64 letters, digits, '_', '.' or '-'";
      return;
    }
    location.hash = "p=" + encodeURIComponent(id);
    begin(id);
  });

  // ---------- the test hook ----------
  // The browser's own decoder (WebCodecs ImageDecoder; reading the file needs Chromium's
  // --allow-file-access-from-files, which the browser test passes) reports the animation's frames.
  function hashOf(image) {
    var c = document.createElement("canvas");
    c.width = image.displayWidth || image.naturalWidth; c.height = image.displayHeight || image.naturalHeight;
    var g = c.getContext("2d");
    g.drawImage(image, 0, 0);
    var d = g.getImageData(0, 0, c.width, c.height).data, h = 0;
    for (var i = 0; i < d.length; i += 4) h = (h * 31 + d[i] + 7 * d[i + 1] + 13 * d[i + 2]) | 0;
    return h;
  }
  function decodeFrames(src, done) {
    if (!window.ImageDecoder) { done({ error: "no ImageDecoder" }); return; }
    var x = new XMLHttpRequest();
    x.open("GET", src);
    x.responseType = "arraybuffer";
    x.onerror = function () { done({ error: "cannot read " + src }); };
    x.onload = function () {
      var d = new ImageDecoder({ data: x.response, type: "image/png" });
      d.tracks.ready.then(function () {
        var n = d.tracks.selectedTrack.frameCount;
        return Promise.all([d.decode({ frameIndex: 0 }), d.decode({ frameIndex: n - 1 })]).then(function (r) {
          done({ frames: n, animated: d.tracks.selectedTrack.animated, first_differs_from_last: hashOf(r[0].image) !== hashOf(r[1].image),
            width: r[0].image.displayWidth, height: r[0].image.displayHeight });
        });
      }).catch(function (e) { done({ error: String(e) }); });
    };
    x.send();
  }
  function runTest(participant) {
    var out = { participant: participant, items: S.items.length, conditions: S.conditions };
    localStorage.removeItem("annotrace-survey:" + S.id + ":" + participant);
    begin(participant);
    out.order = st.order.map(function (sh, k) {
      return { position: k + 1, trace_id: S.items[sh.item].trace_id, condition: S.conditions[sh.condition] };
    });
    var img = $("video");
    function whenLoaded(f) { if (img.complete && img.naturalWidth) f(); else img.addEventListener("load", f, { once: true }); }
    whenLoaded(function () {
      out.video = { width: img.naturalWidth, height: img.naturalHeight, src: img.getAttribute("src") };
      $("replay").click();
      whenLoaded(function () {
        out.replayed = img.complete && img.naturalWidth > 0;
        decodeFrames(img.getAttribute("src"), function (decoded) {
          out.decoded = decoded;
          // Rate every item, moving with the next button.
          for (var k = 0; k < st.order.length; k++) {
            $("rating-" + (1 + (k % 7))).click();
            if (k < st.order.length - 1) $("next").click();
          }
          out.answered = answeredCount();
          out.done_shown = !$("done").hidden;
          out.stored = JSON.parse(localStorage.getItem(key()) || "{}");
          out.csv = csvText();
          out.export_visible = !$("export").hidden;
          // Back to the first item for the screenshot, its rating checked.
          while (st.pos > 0) $("prev").click();
          out.first_checked = (document.querySelector("#scale input:checked") || {}).value || null;
          var pre = $("test-result");
          pre.textContent = JSON.stringify(out);
          pre.dataset.done = "1";
        });
      });
    });
  }

  document.title = S.title;
  $("title").textContent = S.title;
  buildScale();
  var params = hashParams();
  if (params.test && params.p && ID_RE.test(params.p)) runTest(params.p);
  else if (params.p && ID_RE.test(params.p)) begin(params.p);
  else showStart();
})();
