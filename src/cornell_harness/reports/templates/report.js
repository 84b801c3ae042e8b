/* cornell-harness report: theme toggle, sortable table, metric selectors and the HDR image viewer. No dependencies. */
(function () {
  'use strict';

  // ---------------------------------------------------------------- theme
  // The stylesheet follows the system's light/dark preference; the toggle overrides it with data-theme on
  // <html>, remembered in localStorage where the browser allows it (some refuse storage to file:// pages).
  var root = document.documentElement, THEME_KEY = 'cbox-report-theme';
  var prefersDark = window.matchMedia ? window.matchMedia('(prefers-color-scheme: dark)') : null;
  function currentTheme() {
    return root.getAttribute('data-theme') || (prefersDark && prefersDark.matches ? 'dark' : 'light');
  }
  function labelToggle() {
    var b = document.getElementById('theme-toggle');
    if (!b) return;
    var other = currentTheme() === 'dark' ? 'light' : 'dark';
    b.textContent = other === 'light' ? '☀ light' : '☾ dark';
    b.title = 'switch to the ' + other + ' theme';
  }
  function setTheme(theme) {
    root.setAttribute('data-theme', theme);
    try { localStorage.setItem(THEME_KEY, theme); } catch (e) { /* storage refused: this page only */ }
    labelToggle();
  }
  try {
    var saved = localStorage.getItem(THEME_KEY);
    if (saved === 'light' || saved === 'dark') root.setAttribute('data-theme', saved);
  } catch (e) { /* storage refused: follow the system */ }
  var toggle = document.getElementById('theme-toggle');
  if (toggle) toggle.addEventListener('click', function () { setTheme(currentTheme() === 'dark' ? 'light' : 'dark'); });

  // ---------------------------------------------------------------- navigation bar
  // Anchors land below the sticky bar (report.css's scroll-margin-top uses --nav-h): its height, kept current as
  // it wraps to more lines or fewer when the window changes.
  var nav = document.querySelector('nav.toc');
  function keepNavHeight() { root.style.setProperty('--nav-h', nav.getBoundingClientRect().height + 'px'); }
  if (nav) {
    keepNavHeight();
    if (window.ResizeObserver) new ResizeObserver(keepNavHeight).observe(nav);
    else window.addEventListener('resize', keepNavHeight);
  }
  if (prefersDark && prefersDark.addEventListener) prefersDark.addEventListener('change', labelToggle);
  labelToggle();

  // ---------------------------------------------------------------- sortable table
  function sortValue(td) {
    if (!td) return null;
    var s = td.getAttribute('data-sort');
    if (s === null || s === '') return null;
    var n = Number(s);
    return isNaN(n) ? s.toLowerCase() : n;
  }
  Array.prototype.forEach.call(document.querySelectorAll('table.sortable'), function (table) {
    var heads = table.querySelectorAll('thead tr.cols th');
    Array.prototype.forEach.call(heads, function (th) {
      th.addEventListener('click', function () {
        var key = th.getAttribute('data-key');
        var dir = th.getAttribute('data-dir') === 'asc' ? 'desc' : 'asc';
        Array.prototype.forEach.call(heads, function (h) {
          h.removeAttribute('data-dir');
          h.querySelector('.arrow').textContent = '';
        });
        th.setAttribute('data-dir', dir);
        th.querySelector('.arrow').textContent = dir === 'asc' ? '▲' : '▼';
        var body = table.tBodies[0];
        var rows = Array.prototype.slice.call(body.rows);
        rows.forEach(function (r, i) { r._i = i; });
        rows.sort(function (a, b) {
          var va = sortValue(a.querySelector('td[data-key="' + key + '"]'));
          var vb = sortValue(b.querySelector('td[data-key="' + key + '"]'));
          if (va === null && vb === null) return a._i - b._i;
          if (va === null) return 1;  // missing values always last
          if (vb === null) return -1;
          var c = (typeof va === typeof vb) ? (va < vb ? -1 : va > vb ? 1 : 0) : (typeof va === 'number' ? -1 : 1);
          if (dir === 'desc') c = -c;
          return c || a._i - b._i;
        });
        rows.forEach(function (r) { body.appendChild(r); });
      });
    });
  });

  // ---------------------------------------------------------------- metric selectors (all charts follow)
  function setMetric(key) {
    Array.prototype.forEach.call(document.querySelectorAll('[data-metric]'), function (el) {
      el.style.display = el.getAttribute('data-metric') === key ? '' : 'none';
    });
    Array.prototype.forEach.call(document.querySelectorAll('[data-metric-button]'), function (b) {
      b.classList.toggle('active', b.getAttribute('data-metric-button') === key);
    });
  }
  Array.prototype.forEach.call(document.querySelectorAll('[data-metric-button]'), function (b) {
    b.addEventListener('click', function () { setMetric(b.getAttribute('data-metric-button')); });
  });

  // ---------------------------------------------------------------- viewer data
  var dataEl = document.getElementById('cbox-data');
  var canvas = document.getElementById('view');
  if (!dataEl || !canvas) return;
  var D = JSON.parse(dataEl.textContent);
  if (!D.renderers || !D.renderers.length) return;
  var W = D.width, H = D.height, N = W * H;

  // IEEE half -> float, as a 65536-entry table.
  var HALF = new Float32Array(65536);
  for (var h = 0; h < 65536; h++) {
    var sgn = (h & 0x8000) ? -1 : 1, e = (h >> 10) & 0x1f, m = h & 0x3ff;
    HALF[h] = sgn * (e === 0 ? m * Math.pow(2, -24) : e === 31 ? (m ? NaN : Infinity) : (1 + m / 1024) * Math.pow(2, e - 15));
  }
  function decodeF16(b64) {
    var bin = atob(b64), n = bin.length >> 1, out = new Float32Array(n);
    for (var i = 0; i < n; i++) out[i] = HALF[bin.charCodeAt(2 * i) | (bin.charCodeAt(2 * i + 1) << 8)];
    return out;
  }
  function decodeLut(hex) {
    var out = new Uint8Array(768);
    for (var i = 0; i < 768; i++) out[i] = parseInt(hex.substr(2 * i, 2), 16);
    return out;
  }
  var LUTS = {};
  Object.keys(D.colormaps).forEach(function (k) { LUTS[k] = decodeLut(D.colormaps[k]); });

  var REF = decodeF16(D.reference);
  var cache = {};  // lazily decoded arrays per renderer
  function rdata(i) {
    if (!cache[i]) {
      var r = D.renderers[i];
      cache[i] = {
        img: decodeF16(r.img), de: decodeF16(r.de), relmse: decodeF16(r.relmse),
        flip: r.flip ? decodeF16(r.flip) : null
      };
    }
    return cache[i];
  }

  // ---------------------------------------------------------------- tone mapping and colour maps
  function oetf(x) { return x <= 0.0031308 ? 12.92 * x : 1.055 * Math.pow(x, 1 / 2.4) - 0.055; }
  function toneMap(src, stops, out) {
    var k = Math.pow(2, stops) * D.exposure;
    for (var i = 0, j = 0; i < N; i++, j += 4) {
      for (var c = 0; c < 3; c++) {
        var v = src[3 * i + c] * k;
        v = v > 0 ? (v < 1 ? v : 1) : 0;  // NaN -> 0 (black), as the harness's display encoding
        out[j + c] = Math.round(oetf(v) * 255);
      }
      out[j + 3] = 255;
    }
  }
  function colorMap(values, spec, out) {
    var lut = LUTS[spec.cmap], lo = spec.lo, hi = spec.hi;
    for (var i = 0, j = 0; i < N; i++, j += 4) {
      var t = (values[i] - lo) / (hi - lo);
      t = t !== t ? 1 : t < 0 ? 0 : t > 1 ? 1 : t;  // NaN reads as the worst value
      var q = Math.round(t * 255) * 3;
      out[j] = lut[q]; out[j + 1] = lut[q + 1]; out[j + 2] = lut[q + 2]; out[j + 3] = 255;
    }
  }
  function offscreen() {
    var c = document.createElement('canvas'); c.width = W; c.height = H; return c;
  }
  var layerA = offscreen(), layerB = offscreen();  // A: renderer (image or map), B: reference image
  function paint(layer, fill) {
    var ctx = layer.getContext('2d'), id = ctx.createImageData(W, H);
    fill(id.data);
    ctx.putImageData(id, 0, 0);
  }

  // ---------------------------------------------------------------- state
  var S = { r: 0, mode: 'image', flipped: false, split: 0.5, stops: 0, scale: 1, ox: 0, oy: 0, fit: 1, hover: null };
  var ctx = canvas.getContext('2d');
  var dpr = 1, cssW = W, cssH = H;
  var $ = function (id) { return document.getElementById(id); };

  function updateLayers() {
    var d = rdata(S.r);
    paint(layerB, function (out) { toneMap(REF, S.stops, out); });
    paint(layerA, function (out) {
      if (S.mode === 'image') toneMap(d.img, S.stops, out);
      else colorMap(d[S.mode], D.maps[S.mode], out);
    });
  }
  function updateThumbs() {
    Array.prototype.forEach.call(document.querySelectorAll('#picker button'), function (b) {
      var i = Number(b.getAttribute('data-index')), c = b.querySelector('canvas');
      paint(c, function (out) { toneMap(rdata(i).img, S.stops, out); });
    });
  }

  function resize() {
    var newW = Math.max(120, Math.floor(canvas.parentNode.clientWidth || W));
    var newH = Math.round(newW * H / W);
    dpr = window.devicePixelRatio || 1;
    var cx = S.ox + cssW / S.scale / 2, cy = S.oy + cssH / S.scale / 2, rel = S.scale / S.fit;
    cssW = newW; cssH = newH;
    canvas.style.height = cssH + 'px';
    canvas.width = Math.round(cssW * dpr); canvas.height = Math.round(cssH * dpr);
    S.fit = cssW / W;
    S.scale = S.fit * rel;
    S.ox = cx - cssW / S.scale / 2; S.oy = cy - cssH / S.scale / 2;
    clampPan();
    draw();
  }
  function clampPan() {
    var vw = cssW / S.scale, vh = cssH / S.scale;
    S.ox = vw >= W ? (W - vw) / 2 : Math.min(Math.max(S.ox, 0), W - vw);
    S.oy = vh >= H ? (H - vh) / 2 : Math.min(Math.max(S.oy, 0), H - vh);
  }

  function draw() {
    var k = S.scale * dpr;
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = '#0b0c0e';
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    ctx.imageSmoothingEnabled = false;
    var left = S.flipped ? layerB : layerA, right = S.flipped ? layerA : layerB;
    var sx = Math.round(S.split * canvas.width);
    ctx.setTransform(k, 0, 0, k, -S.ox * k, -S.oy * k);
    ctx.drawImage(left, 0, 0);
    ctx.save();
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.beginPath(); ctx.rect(sx, 0, canvas.width - sx, canvas.height); ctx.clip();
    ctx.setTransform(k, 0, 0, k, -S.ox * k, -S.oy * k);
    ctx.drawImage(right, 0, 0);
    ctx.restore();
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    if (k >= 16 && S.scale > S.fit * 1.01) {  // pixel grid once zoomed in to large pixels
      ctx.strokeStyle = 'rgba(255,255,255,0.12)'; ctx.lineWidth = 1;
      ctx.beginPath();
      var x0 = Math.floor(S.ox), x1 = Math.ceil(S.ox + cssW / S.scale), y0 = Math.floor(S.oy), y1 = Math.ceil(S.oy + cssH / S.scale);
      for (var x = x0; x <= x1; x++) { var px = Math.round((x - S.ox) * k) + 0.5; ctx.moveTo(px, 0); ctx.lineTo(px, canvas.height); }
      for (var y = y0; y <= y1; y++) { var py = Math.round((y - S.oy) * k) + 0.5; ctx.moveTo(0, py); ctx.lineTo(canvas.width, py); }
      ctx.stroke();
    }
    if (S.hover && k >= 6) {
      ctx.strokeStyle = '#ffd166'; ctx.lineWidth = Math.max(1, dpr);
      ctx.strokeRect((S.hover[0] - S.ox) * k, (S.hover[1] - S.oy) * k, k, k);
    }
    if (S.split > 0 && S.split < 1) {
      ctx.fillStyle = 'rgba(255,255,255,0.85)';
      ctx.fillRect(sx - Math.max(1, dpr) / 2, 0, Math.max(1, dpr), canvas.height);
    }
    var rname = (D.renderers[S.r].label || D.renderers[S.r].name) + (S.mode === 'image' ? '' : ' · ' + D.maps[S.mode].label);
    $('tag-left').textContent = S.flipped ? 'reference' : rname;
    $('tag-right').textContent = S.flipped ? rname : 'reference';
    $('tag-left').style.display = S.split > 0 ? '' : 'none';
    $('tag-right').style.display = S.split < 1 ? '' : 'none';
    $('zoom-val').textContent = fmtZoom(S.scale / S.fit) + ' (' + fmtZoom(S.scale) + ' px/pixel)';
  }
  function fmtZoom(z) { return (z >= 10 ? Math.round(z) : Math.round(z * 10) / 10) + '×'; }

  function refresh() { updateLayers(); draw(); updateReadout(); }

  // ---------------------------------------------------------------- readout
  function fmt(v) {
    if (v !== v) return 'NaN';
    if (!isFinite(v)) return v > 0 ? '∞' : '−∞';
    if (v === 0) return '0';
    var a = Math.abs(v);
    return (a >= 1e4 || a < 1e-3) ? v.toExponential(2) : v.toPrecision(4);
  }
  function updateReadout() {
    var p = S.hover, d = rdata(S.r);
    $('ro-name').textContent = D.renderers[S.r].label || D.renderers[S.r].name;
    if (!p) {
      ['ro-xy', 'ro-r0', 'ro-r1', 'ro-r2', 'ro-f0', 'ro-f1', 'ro-f2', 'ro-de', 'ro-rel', 'ro-flip'].forEach(function (id) { $(id).textContent = '—'; });
      return;
    }
    var i = p[1] * W + p[0];
    $('ro-xy').textContent = p[0] + ', ' + p[1];
    for (var c = 0; c < 3; c++) {
      $('ro-r' + c).textContent = fmt(d.img[3 * i + c]);
      $('ro-f' + c).textContent = fmt(REF[3 * i + c]);
    }
    $('ro-de').textContent = fmt(d.de[i]);
    $('ro-rel').textContent = d.relmse[i] <= -12 ? '0' : fmt(Math.pow(10, d.relmse[i]));
    $('ro-flip').textContent = d.flip ? fmt(d.flip[i]) : 'n/a';
  }

  // ---------------------------------------------------------------- interaction
  function setMode(mode) {
    if (mode === 'flip' && !D.maps.flip.available) return;
    S.mode = mode;
    Array.prototype.forEach.call(document.querySelectorAll('#modes button'), function (b) {
      b.classList.toggle('active', b.getAttribute('data-mode') === mode);
    });
    Array.prototype.forEach.call(document.querySelectorAll('#legends .legend'), function (l) {
      l.classList.toggle('active', l.getAttribute('data-legend') === mode);
    });
    refresh();
  }
  function setRenderer(i) {
    S.r = (i + D.renderers.length) % D.renderers.length;
    Array.prototype.forEach.call(document.querySelectorAll('#picker button'), function (b) {
      b.setAttribute('aria-pressed', Number(b.getAttribute('data-index')) === S.r ? 'true' : 'false');
    });
    refresh();
  }
  function setFlipped(f) {
    S.flipped = f;
    $('flip-toggle').setAttribute('aria-pressed', f ? 'true' : 'false');
    draw();
  }
  function setStops(v) {
    S.stops = Math.max(-8, Math.min(8, Math.round(v * 10) / 10));
    $('exposure').value = S.stops;
    $('exposure-val').textContent = (S.stops >= 0 ? '+' : '−') + Math.abs(S.stops).toFixed(1) + ' EV';
    updateLayers(); updateThumbs(); draw();
  }
  function zoomAt(factor, mx, my) {
    var ns = Math.max(S.fit, Math.min(S.fit * 64, S.scale * factor));
    var ix = S.ox + mx / S.scale, iy = S.oy + my / S.scale;
    S.scale = ns;
    S.ox = ix - mx / ns; S.oy = iy - my / ns;
    clampPan(); draw();
  }

  Array.prototype.forEach.call(document.querySelectorAll('#modes button'), function (b) {
    b.addEventListener('click', function () { setMode(b.getAttribute('data-mode')); });
  });
  Array.prototype.forEach.call(document.querySelectorAll('#picker button'), function (b) {
    b.addEventListener('click', function () { setRenderer(Number(b.getAttribute('data-index'))); });
  });
  $('flip-toggle').addEventListener('click', function () { setFlipped(!S.flipped); });
  $('split').addEventListener('input', function () { S.split = Number(this.value) / 100; draw(); });
  $('exposure').addEventListener('input', function () { setStops(Number(this.value)); });
  $('exposure-reset').addEventListener('click', function () { setStops(0); });
  $('zoom-in').addEventListener('click', function () { zoomAt(2, cssW / 2, cssH / 2); });
  $('zoom-out').addEventListener('click', function () { zoomAt(0.5, cssW / 2, cssH / 2); });
  $('zoom-fit').addEventListener('click', function () { S.scale = S.fit; S.ox = S.oy = 0; clampPan(); draw(); });

  function local(ev) {
    var r = canvas.getBoundingClientRect();
    return [ev.clientX - r.left, ev.clientY - r.top];
  }
  canvas.addEventListener('wheel', function (ev) {
    ev.preventDefault();
    var p = local(ev);
    if (ev.shiftKey) {
      S.ox += (ev.deltaY || ev.deltaX) / S.scale; S.oy += (ev.deltaX && ev.deltaY ? ev.deltaY : 0) / S.scale;
      clampPan(); draw();
    } else {
      zoomAt(Math.pow(1.0015, -ev.deltaY), p[0], p[1]);
    }
  }, { passive: false });
  var drag = null;
  canvas.addEventListener('pointerdown', function (ev) {
    drag = { x: ev.clientX, y: ev.clientY, ox: S.ox, oy: S.oy };
    canvas.classList.add('dragging');
    if (canvas.setPointerCapture) canvas.setPointerCapture(ev.pointerId);
  });
  canvas.addEventListener('pointermove', function (ev) {
    if (drag) {
      S.ox = drag.ox - (ev.clientX - drag.x) / S.scale;
      S.oy = drag.oy - (ev.clientY - drag.y) / S.scale;
      clampPan();
    }
    var p = local(ev);
    var ix = Math.floor(S.ox + p[0] / S.scale), iy = Math.floor(S.oy + p[1] / S.scale);
    S.hover = (ix >= 0 && iy >= 0 && ix < W && iy < H) ? [ix, iy] : null;
    draw(); updateReadout();
  });
  function endDrag() { drag = null; canvas.classList.remove('dragging'); }
  canvas.addEventListener('pointerup', endDrag);
  canvas.addEventListener('pointercancel', endDrag);
  canvas.addEventListener('pointerleave', function () { if (!drag) { S.hover = null; draw(); updateReadout(); } });

  document.addEventListener('keydown', function (ev) {
    if (ev.ctrlKey || ev.metaKey || ev.altKey) return;
    var t = ev.target && ev.target.tagName;
    if (t === 'INPUT' && ev.target.type !== 'range' || t === 'TEXTAREA' || t === 'SELECT') return;
    var k = ev.key, handled = true;
    if (k === 'f' || k === 'F') setFlipped(!S.flipped);
    else if (k === '1') setMode('image');
    else if (k === '2') setMode('de');
    else if (k === '3') setMode('relmse');
    else if (k === '4') setMode('flip');
    else if (k === '[') setStops(S.stops - 0.5);
    else if (k === ']') setStops(S.stops + 0.5);
    else if (k === 'r' || k === 'R') setStops(0);
    else if (k === '+' || k === '=') zoomAt(2, cssW / 2, cssH / 2);
    else if (k === '-' || k === '_') zoomAt(0.5, cssW / 2, cssH / 2);
    else if (k === '0') { S.scale = S.fit; S.ox = S.oy = 0; clampPan(); draw(); }
    else if ((k === 'ArrowDown' || k === 'ArrowUp') && t !== 'INPUT') setRenderer(S.r + (k === 'ArrowDown' ? 1 : -1));
    else handled = false;
    if (handled) ev.preventDefault();
  });
  window.addEventListener('resize', resize);

  updateLayers();
  updateThumbs();
  resize();
  updateReadout();
  // A handle for tests and the curious: the viewer's state, read-only by convention.
  window.cboxViewer = { state: S, setMode: setMode, setRenderer: setRenderer, setFlipped: setFlipped, setStops: setStops, zoomAt: zoomAt };
})();
