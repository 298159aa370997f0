// mapqual dashboard: reload while something runs; sortable tables.
(function () {
  "use strict";
  const refresh = document.querySelector('meta[name="mapqual-refresh"]');
  if (refresh) {
    // The countdown starts once the page has loaded (on a slow server a page reloading
    // before its own load would never finish loading), and stops when the user leaves: a
    // reload must not cancel the link or form the user chose while waiting for it.
    const seconds = parseFloat(refresh.content) || 3;
    let timer = null;
    const arm = function () {
      timer = setTimeout(function () {
        // keep the scroll position across the reload
        sessionStorage.setItem("mapqual-scroll", String(window.scrollY));
        window.location.reload();
      }, seconds * 1000);
    };
    if (document.readyState === "complete") { arm(); } else { window.addEventListener("load", arm); }
    const disarm = function () { window.removeEventListener("load", arm); clearTimeout(timer); };
    window.addEventListener("beforeunload", disarm);
    document.addEventListener("submit", disarm);
    // a link into this tab (one opening another tab, like the viewer's, leaves it refreshing)
    document.addEventListener("click", function (e) {
      const a = e.target.closest("a[href]");
      if (a && (!a.target || a.target === "_self") && !e.ctrlKey && !e.metaKey && !e.shiftKey) { disarm(); }
    });
  }
  const y = sessionStorage.getItem("mapqual-scroll");
  if (y !== null) { sessionStorage.removeItem("mapqual-scroll"); window.scrollTo(0, parseFloat(y)); }

  function cellValue(td) {
    const v = td.dataset.v !== undefined ? td.dataset.v : td.textContent.trim();
    const n = parseFloat(v);
    return isNaN(n) ? v.toLowerCase() : n;
  }
  document.querySelectorAll("table.sortable").forEach(function (table) {
    const body = table.tBodies[0];
    // the last header row holds one th per column once row/colspans are unfolded
    const heads = [];
    Array.from(table.tHead.rows[0].cells).forEach(function (th) {
      if (th.colSpan > 1) {
        Array.from(table.tHead.rows[1].cells).slice(heads.filter(h => h.sub).length, heads.filter(h => h.sub).length + th.colSpan)
          .forEach(function (sub) { heads.push({ th: sub, sub: true }); });
      } else { heads.push({ th: th, sub: false }); }
    });
    heads.forEach(function (h, col) {
      h.th.addEventListener("click", function () {
        const asc = !h.th.classList.contains("asc");
        table.querySelectorAll("th").forEach(t => t.classList.remove("asc", "desc"));
        h.th.classList.add(asc ? "asc" : "desc");
        const rows = Array.from(body.rows).filter(r => r.cells.length === heads.length);
        rows.sort(function (a, b) {
          const x = cellValue(a.cells[col]), y = cellValue(b.cells[col]);
          return (x < y ? -1 : x > y ? 1 : 0) * (asc ? 1 : -1);
        });
        rows.forEach(r => body.appendChild(r));
      });
    });
  });
})();

// The zoom view: a click on a plot opens it over the whole window, at a higher resolution
// where the server draws one (data-zoom), with pan (drag), zoom (wheel, +/-, buttons, double
// click), fit (0) and close (Esc); the PNG (and the figure's CSV, if any) stay downloadable.
(function () {
  "use strict";
  const plots = document.querySelectorAll("figure img");
  if (!plots.length) { return; }
  const box = document.createElement("div");
  box.id = "zoom-view";
  box.setAttribute("role", "dialog");
  box.setAttribute("aria-modal", "true");
  box.hidden = true;
  box.innerHTML = '<div class="zoom-bar"><span class="zoom-title"></span>' +
    '<button type="button" data-act="out" title="zoom out (-)">&minus;</button>' +
    '<span class="zoom-level"></span>' +
    '<button type="button" data-act="in" title="zoom in (+)">+</button>' +
    '<button type="button" data-act="fit" title="fit to the window (0)">fit</button>' +
    '<button type="button" data-act="one" title="one image pixel per screen pixel (1)">1:1</button>' +
    '<a class="zoom-png" download>PNG</a><a class="zoom-csv" download hidden>CSV</a>' +
    '<button type="button" data-act="close" title="close (Esc)">&times; close</button></div>' +
    '<div class="zoom-stage"><img alt=""></div>';
  document.body.appendChild(box);
  const stage = box.querySelector(".zoom-stage"), img = stage.querySelector("img");
  const level = box.querySelector(".zoom-level");
  const view = { s: 1, x: 0, y: 0, fit: 1 };
  function draw() {
    img.style.transform = "translate(" + view.x + "px," + view.y + "px) scale(" + view.s + ")";
    level.textContent = Math.round(100 * view.s / view.fit) + " %";
    box.dataset.scale = String(view.s / view.fit);
  }
  function fit() {
    const w = img.naturalWidth || 1, h = img.naturalHeight || 1;
    view.fit = view.s = Math.min(stage.clientWidth / w, stage.clientHeight / h);
    view.x = (stage.clientWidth - w * view.s) / 2; view.y = (stage.clientHeight - h * view.s) / 2;
    draw();
  }
  function zoom(factor, cx, cy) {  // about the stage point (cx, cy)
    const s = Math.min(Math.max(view.s * factor, view.fit * 0.5), view.fit * 20);
    if (cx === undefined) { cx = stage.clientWidth / 2; cy = stage.clientHeight / 2; }
    view.x = cx - (cx - view.x) * s / view.s; view.y = cy - (cy - view.y) * s / view.s;
    view.s = s; draw();
  }
  function open(src, title, png, csv) {
    box.hidden = false; document.body.classList.add("zooming");
    box.querySelector(".zoom-title").textContent = title;
    box.querySelector(".zoom-png").href = png;
    const c = box.querySelector(".zoom-csv"); c.hidden = !csv; if (csv) { c.href = csv; }
    box.dataset.loaded = "0";
    img.onload = function () { fit(); box.dataset.loaded = "1"; };
    img.src = src;
    if (img.complete && img.naturalWidth) { img.onload(); }
  }
  function close() { box.hidden = true; document.body.classList.remove("zooming"); img.removeAttribute("src"); }
  plots.forEach(function (p) {
    p.classList.add("zoomable");
    p.title = "click to enlarge (zoom and pan)";
    const fig = p.closest("figure"), link = p.closest("a");
    (link || p).addEventListener("click", function (e) {
      if (e.ctrlKey || e.metaKey || e.shiftKey) { return; }  // a new tab, as before
      e.preventDefault();
      const src = p.getAttribute("data-zoom") || p.getAttribute("src");
      open(src, p.alt, src, fig && fig.getAttribute("data-csv"));
    });
  });
  box.querySelector(".zoom-bar").addEventListener("click", function (e) {
    const act = e.target.dataset && e.target.dataset.act;
    if (act === "in") { zoom(1.5); } else if (act === "out") { zoom(1 / 1.5); }
    else if (act === "fit") { fit(); } else if (act === "one") { zoom(1 / view.s); }
    else if (act === "close") { close(); }
  });
  stage.addEventListener("wheel", function (e) {
    e.preventDefault();
    const r = stage.getBoundingClientRect();
    zoom(Math.exp(-e.deltaY / 300), e.clientX - r.left, e.clientY - r.top);
  }, { passive: false });
  stage.addEventListener("dblclick", function (e) {
    const r = stage.getBoundingClientRect();
    zoom(2, e.clientX - r.left, e.clientY - r.top);
  });
  let drag = null;
  stage.addEventListener("pointerdown", function (e) {
    drag = { x: e.clientX - view.x, y: e.clientY - view.y }; stage.setPointerCapture(e.pointerId);
  });
  stage.addEventListener("pointermove", function (e) {
    if (drag) { view.x = e.clientX - drag.x; view.y = e.clientY - drag.y; draw(); }
  });
  stage.addEventListener("pointerup", function () { drag = null; });
  document.addEventListener("keydown", function (e) {
    if (box.hidden) { return; }
    if (e.key === "Escape") { close(); } else if (e.key === "+" || e.key === "=") { zoom(1.5); }
    else if (e.key === "-") { zoom(1 / 1.5); } else if (e.key === "0") { fit(); }
    else if (e.key === "1") { zoom(1 / view.s); }
  });
  window.addEventListener("resize", function () { if (!box.hidden) { fit(); } });
})();
