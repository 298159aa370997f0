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
