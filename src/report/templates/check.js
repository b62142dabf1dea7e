document.addEventListener("DOMContentLoaded", function () {
  var plots = document.querySelectorAll("figure.plot");
  var ok = true;
  plots.forEach(function (f) {
    var svg = f.querySelector("svg");
    var n = Number(f.getAttribute("data-points"));
    var box = svg ? svg.getBBox() : null;
    if (!svg || !(n > 0) || !box || box.width <= 0) { ok = false; f.setAttribute("data-empty", "true"); }
  });
  document.body.setAttribute("data-plots", String(plots.length));
  document.body.setAttribute("data-plots-ok", String(ok));
});
