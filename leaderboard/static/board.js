/* dg16m leaderboard: sortable tables. Plain JS, no libraries, nothing fetched.
 *
 * The page is complete without this script. It makes every header cell with a data-sort
 * attribute sortable: a click (or Enter / Space when focused) sorts the rows of its table by the
 * data-value attributes of that column's cells (the cell text when there is none): numerically
 * when both values parse as numbers, else as text. A second click reverses the order. Empty
 * values ("—") always go last; ties keep the order the page was served in. The direction shows
 * in the header's aria-sort attribute. A header's data-first attribute ("ascending" or
 * "descending") sets the direction of its first click.
 */
(function () {
  "use strict";

  var NUMBER = /^\s*[-+]?(\d+(\.\d*)?|\.\d+)([eE][-+]?\d+)?\s*$/;
  var collator = new Intl.Collator(undefined, { numeric: true, sensitivity: "base" });

  function cellValue(row, index) {
    var cell = row.cells[index];
    if (!cell) {
      return "";
    }
    var value = cell.getAttribute("data-value");
    return (value === null ? cell.textContent : value).trim();
  }

  function compareValues(a, b) {
    if (NUMBER.test(a) && NUMBER.test(b)) {
      return parseFloat(a) - parseFloat(b);
    }
    return collator.compare(a, b);
  }

  function sortTable(table, header, direction) {
    var body = table.tBodies[0];
    if (!body) {
      return;
    }
    var index = header.cellIndex;
    var sign = direction === "descending" ? -1 : 1;
    var rows = Array.prototype.slice.call(body.rows).map(function (row) {
      return { row: row, value: cellValue(row, index), order: Number(row.dataset.order) };
    });
    rows.sort(function (x, y) {
      var xEmpty = x.value === "";
      var yEmpty = y.value === "";
      if (xEmpty !== yEmpty) {
        return xEmpty ? 1 : -1;
      }
      var c = xEmpty ? 0 : sign * compareValues(x.value, y.value);
      return c !== 0 ? c : x.order - y.order;
    });
    var fragment = document.createDocumentFragment();
    rows.forEach(function (item) {
      fragment.appendChild(item.row);
    });
    body.appendChild(fragment);
    Array.prototype.forEach.call(table.querySelectorAll("th[data-sort]"), function (th) {
      if (th === header) {
        th.setAttribute("aria-sort", direction);
      } else {
        th.removeAttribute("aria-sort");
      }
    });
  }

  function nextDirection(header) {
    var current = header.getAttribute("aria-sort");
    if (current === "ascending") {
      return "descending";
    }
    if (current === "descending") {
      return "ascending";
    }
    return header.getAttribute("data-first") === "descending" ? "descending" : "ascending";
  }

  function enhance(table) {
    Array.prototype.forEach.call(table.tBodies, function (body) {
      Array.prototype.forEach.call(body.rows, function (row, i) {
        row.dataset.order = String(i);
      });
    });
    Array.prototype.forEach.call(table.querySelectorAll("thead th[data-sort]"), function (th) {
      th.classList.add("sortable");
      th.tabIndex = 0;
      th.title = "Sort by this column";
      function activate(event) {
        if (event.target.closest && event.target.closest("a")) {
          return;
        }
        sortTable(table, th, nextDirection(th));
      }
      th.addEventListener("click", activate);
      th.addEventListener("keydown", function (event) {
        if (event.key === "Enter" || event.key === " ") {
          event.preventDefault();
          activate(event);
        }
      });
    });
  }

  function init() {
    document.documentElement.classList.add("js");
    Array.prototype.forEach.call(document.querySelectorAll("table"), function (table) {
      if (table.querySelector("thead th[data-sort]")) {
        enhance(table);
      }
    });
  }

  if (document.readyState === "loading") {
    document.addEventListener("DOMContentLoaded", init);
  } else {
    init();
  }
})();
