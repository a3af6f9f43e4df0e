// avard web: swaps in the fragments the server sends as server-sent events.
// Hand-written, no library; the plots are SVG drawn by the server.
(function () {
  "use strict";
  var params = new URLSearchParams(window.location.search);
  var target = params.get("target");
  var url = "/events" + (target ? "?target=" + encodeURIComponent(target) : "");
  var conn = document.getElementById("conn");
  var updates = 0;

  function show(text, cls) {
    conn.textContent = text;
    conn.className = cls;
  }

  if (!window.EventSource) {
    show("this browser cannot receive live updates; reload to refresh", "down");
    return;
  }
  var source = new EventSource(url);
  source.addEventListener("update", function (ev) {
    var parts = JSON.parse(ev.data);
    Object.keys(parts).forEach(function (id) {
      var el = document.getElementById(id);
      if (el) { el.innerHTML = parts[id]; }
    });
    updates += 1;
    document.body.setAttribute("data-updates", String(updates));
    show("live — updated " + new Date().toLocaleTimeString(), "live");
  });
  source.addEventListener("open", function () { show("live", "live"); });
  source.addEventListener("error", function () {
    show("connection lost — reconnecting…", "down");
  });
}());
