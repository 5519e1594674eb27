// swarmloc leaderboard: sortable tables, no dependencies.
// Every <table class="sortable"> gets clickable column headers. A header's data-type
// ("number" or "text") says how to compare; cells carry their sort key in data-value
// (empty = missing, always sorted last). Clicking toggles ascending / descending and
// sets aria-sort so assistive technology announces the order.
"use strict";

(function () {
  function sortKey(row, index) {
    var cell = row.children[index];
    if (!cell) {
      return "";
    }
    var value = cell.getAttribute("data-value");
    return value === null ? cell.textContent.trim() : value;
  }

  function compare(a, b, type) {
    if (type === "number") {
      return parseFloat(a) - parseFloat(b);
    }
    return a.localeCompare(b, undefined, { numeric: true, sensitivity: "base" });
  }

  function sortTable(table, index, type, direction) {
    var body = table.tBodies[0];
    var rows = Array.prototype.slice.call(body.rows);
    var sign = direction === "ascending" ? 1 : -1;
    rows.sort(function (rowA, rowB) {
      var a = sortKey(rowA, index);
      var b = sortKey(rowB, index);
      if (a === "" || b === "") {
        return (a === "") - (b === "");  // missing values last in both directions
      }
      return sign * compare(a, b, type);
    });
    rows.forEach(function (row) {
      body.appendChild(row);
    });
    Array.prototype.forEach.call(table.tHead.rows[0].cells, function (th, i) {
      if (i === index) {
        th.setAttribute("aria-sort", direction);
      } else {
        th.removeAttribute("aria-sort");
      }
    });
  }

  function init(table) {
    Array.prototype.forEach.call(table.tHead.rows[0].cells, function (th, index) {
      var button = th.querySelector("button");
      if (!button) {
        return;
      }
      button.addEventListener("click", function () {
        var type = th.getAttribute("data-type") || "text";
        var current = th.getAttribute("aria-sort");
        var direction = current === "ascending" ? "descending" : "ascending";
        sortTable(table, index, type, direction);
      });
    });
  }

  document.addEventListener("DOMContentLoaded", function () {
    Array.prototype.forEach.call(document.querySelectorAll("table.sortable"), init);
    document.documentElement.setAttribute("data-sortable-ready", "true");
  });
})();
