// mapqual dashboard: reload while something runs; sortable tables.
(function () {
  "use strict";
  const refresh = document.querySelector('meta[name="mapqual-refresh"]');
  if (refresh) {
    const seconds = parseFloat(refresh.content) || 3;
    setTimeout(function () {
      // keep the scroll position across the reload
      sessionStorage.setItem("mapqual-scroll", String(window.scrollY));
      window.location.reload();
    }, seconds * 1000);
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
