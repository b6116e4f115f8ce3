/* AlphaFence live map: what the monitor sees, pushed over a WebSocket (/ws on the page's own
 * server, with the page's ?token=) and drawn on the map alphafence-map.js made (window.afMap).
 *
 * Messages (JSON): hello {events}, vehicle {lat, lon, heading_deg, speed_mps, level, path,
 * stop, ...}, fences {center, radius_m, geojson}, onboard {geojson, cause, items},
 * traffic {aircraft: [{lat, lon, radius_m, conflict, ...}]}, event {event}, dropped {messages}.
 * Nothing is ever sent back: the page is read-only.
 *
 * For tests: window.afLive = {connected, vehicle (the latest message), marker (its L.Marker),
 * positions, events (every event received), fences, onboard, traffic, dropped, layers}.
 */
(function () {
  "use strict";
  var map = window.afMap;
  if (!map) return;
  function esc(text) {
    return String(text).replace(/[&<>"']/g, function (c) {
      return {"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;"}[c];
    });
  }
  var KIND = {keep_out: "#c62828", warning: "#ef8f00", keep_in: "#2e7d32"};
  var LEVEL = {CLEAR: "#2e7d32", WARNING: "#ef8f00", IMMINENT: "#d84315", BREACH: "#b71c1c",
               UNKNOWN: "#616161"};
  var ONBOARD = "#1565c0";
  var TRACK_MAX = 5000, EVENTS_SHOWN = 8;

  var live = window.afLive = {connected: false, vehicle: null, marker: null, positions: 0,
    events: [], fences: 0, onboard: 0, onboardCause: null, traffic: 0, dropped: 0};

  function fmt(v, unit) { return v == null ? "-" : v + (unit || ""); }

  function fencePopup(p) {
    var rows = [["kind", p.kind], ["category", p.category], ["site", p.site_id],
      ["margin", fmt(p.margin_m, " m")],
      ["band", (p.alt_min_m == null ? "ground" : p.alt_min_m + " m") + " to " +
               (p.alt_max_m == null ? "unlimited" : p.alt_max_m + " m")]];
    if (p.radius_m != null) rows.push(["radius", p.radius_m + " m"]);
    if (p.vertices != null) rows.push(["vertices", p.vertices]);
    if (p.area_m2 != null) rows.push(["area", Math.round(p.area_m2) + " m\u00b2"]);
    if (p.source_zone != null) rows.push(["live zone", p.source_zone]);
    var window_ = windowText((p.zone || {}).applicability);
    if (window_) rows.push(["in force", window_]);
    return window.AlphaFence.popupHtml({title: p.name || p.site_id, popup: rows.filter(
      function (r) { return r[1] != null; })});
  }

  var fences = L.geoJSON(null, {
    style: function (f) {
      var k = (f.properties || {}).kind, live_ = (f.properties || {}).source_zone != null;
      return {color: KIND[k] || "#555", weight: live_ ? 3 : 1.5,
              fillOpacity: k === "keep_out" ? (live_ ? 0.3 : 0.15) : 0,
              dashArray: k === "warning" ? "5 4" : null};
    }
  }).bindPopup(function (l) { return fencePopup(l.feature.properties || {}); }).addTo(map);
  var onboard = L.geoJSON(null, {
    style: function () { return {color: ONBOARD, weight: 2, dashArray: "6 4", fillOpacity: 0.05}; },
    pointToLayer: function (f, latlng) {
      return L.circle(latlng, {radius: f.properties.radius_m, color: ONBOARD, weight: 2,
                               dashArray: "6 4", fillOpacity: 0.05});
    }
  }).bindPopup(function (l) {
    var p = l.feature.properties;
    return window.AlphaFence.popupHtml({title: p.name, popup: [["kind", p.kind],
      ["shape", p.shape], ["items", p.items]]});
  }).addTo(map);
  // the offline basemap (roads, water, place names of an OSM extract): beneath everything
  var WATER = "#9ecae1", ROAD = {motorway: 3, trunk: 3, primary: 2.5, secondary: 2, tertiary: 1.5};
  var basemap = L.geoJSON(null, {
    style: function (f) {
      var p = f.properties || {};
      if (p.layer === "water") return {color: WATER, weight: 1, fillColor: WATER, fillOpacity: 0.6};
      return {color: "#b0b0b0", weight: ROAD[p["class"]] || 1, opacity: 0.9};
    },
    pointToLayer: function (f, latlng) {
      return L.circleMarker(latlng, {radius: 2, color: "#555", weight: 1, fillOpacity: 1})
        .bindTooltip(f.properties.name, {permanent: true, direction: "right",
                                         className: "af-place"});
    },
    interactive: false
  });
  var track = L.polyline([], {color: "#455a64", weight: 2, opacity: 0.7}).addTo(map);
  var path = L.polyline([], {color: "#6a1b9a", weight: 3, dashArray: "8 6"});
  var stop = L.circleMarker([0, 0], {radius: 5, color: "#6a1b9a", fillColor: "#fff",
                                      fillOpacity: 1, weight: 2});
  var prediction = L.layerGroup([path, stop]);
  var traffic = L.layerGroup().addTo(map);
  var eventMarks = L.layerGroup().addTo(map);
  var arrow = function (heading, color) {
    var turn = heading == null ? 0 : heading;
    var shape = heading == null
      ? '<circle cx="14" cy="14" r="7" fill="' + color + '" stroke="#fff" stroke-width="2"/>'
      : '<path d="M14 2 L23 24 L14 19 L5 24 Z" fill="' + color +
        '" stroke="#fff" stroke-width="2"/>';
    return L.divIcon({className: "af-vehicle", iconSize: [28, 28], iconAnchor: [14, 14],
      html: '<svg width="28" height="28" style="transform:rotate(' + turn + 'deg)">' +
            shape + "</svg>"});
  };
  var marker = L.marker([0, 0], {icon: arrow(null, LEVEL.CLEAR), zIndexOffset: 1000,
                                  keyboard: false});
  live.marker = marker;
  live.layers = {fences: fences, onboard: onboard, track: track, prediction: prediction,
                 traffic: traffic, events: eventMarks};

  var control = map.afControl || L.control.layers(null, {}, {collapsed: false}).addTo(map);
  control.addOverlay(fences, "fences near the vehicle");
  control.addOverlay(onboard, "the vehicle's own fence");
  control.addOverlay(prediction, "predicted path and stop");
  control.addOverlay(track, "track");
  control.addOverlay(traffic, "other aircraft");
  control.addOverlay(eventMarks, "events");
  control.addOverlay(basemap, "basemap (OpenStreetMap extract)");

  function panel(position, cls) {
    var c = L.control({position: position});
    c.onAdd = function () {
      var div = L.DomUtil.create("div", "af-legend " + cls);
      L.DomEvent.disableClickPropagation(div);
      return div;
    };
    c.addTo(map);
    return c.getContainer();
  }
  // the map script's legend has nothing to list here (the layers come later): hidden
  Array.prototype.forEach.call(document.querySelectorAll(".af-legend"), function (el) {
    if (!el.textContent.trim()) el.style.display = "none";
  });
  var status = panel("topleft", "af-status");
  var list = panel("bottomright", "af-events");

  function windowText(a) {
    if (!a) return null;
    return (Array.isArray(a) ? a : [a]).map(function (w) {
      return (w.startDateTime || "\u2026") + " \u2192 " + (w.endDateTime || "\u2026");
    }).join(", ");
  }

  function eventText(e) {
    if (e.event === "source_zone") {
      var w = windowText(e.applicability);
      return (e.change === "new" ? "new zone " : "zone changed ") + (e.name || e.zone) + " (" +
        (e.kinds || []).join(", ") + "; " + e.window + (w ? ": " + w : "") + ") from " +
        (e.source || "the source");
    }
    if (e.event === "source_zone_window") return "zone " + (e.name || e.zone) + ": " + e.window;
    if (e.event === "source_zone_removed") return "zone lifted: " + (e.name || e.zone);
    if (e.event === "level") {
      return e.previous + " \u2192 " + e.level + " " + (e.fence || "") + " (" + e.reason +
        ", " + fmt(e.distance_m, " m") + ")";
    }
    if (e.event === "onboard_fence") return "the vehicle's fence: " + e.items + " items";
    if (e.event === "onboard_upload") {
      return "fence uploaded (" + e.reason + "): " + e.items + " items, " + e.bytes + " B";
    }
    return e.event.replace(/_/g, " ") + " " + (e.action || e.reason || e.error || "");
  }

  function drawStatus() {
    var v = live.vehicle;
    var level = v ? v.level : "-";
    status.innerHTML = '<div class="af-title">AlphaFence live</div>' +
      '<div class="af-row"><span class="af-swatch" style="border-color:' +
      (LEVEL[level] || "#999") + ";background:" + (LEVEL[level] || "#999") + '"></span>' +
      '<b class="af-level">' + esc(level) + "</b></div>" +
      (v ? "<div>" + esc(fmt(v.speed_mps, " m/s")) + ", heading " +
        esc(fmt(v.heading_deg, "\u00b0")) + ", " + esc(fmt(v.alt_m, " m")) + " above home" +
        "</div><div>" + esc(v.mode || "") + (v.armed ? " armed" : "") + ", stops in " +
        esc(fmt(v.stopping_m, " m")) + "</div>" : "") +
      '<div class="af-note">' + (live.connected ? "connected" : "not connected") +
      (live.dropped ? ", " + live.dropped + " messages dropped" : "") + "</div>";
  }

  function drawEvents() {
    var shown = live.events.filter(function (e) { return e.event !== "clock"; })
      .slice(-EVENTS_SHOWN).reverse();
    list.innerHTML = '<div class="af-title">events</div>' + shown.map(function (e) {
      var when = e.utc ? e.utc.slice(11, 19) : fmt(e.time);
      var color = LEVEL[e.level] || "#333";
      return '<div class="af-event af-event-' + esc(e.event) + '" style="color:' + color +
        '">' + esc(when) + " " + esc(eventText(e)) + "</div>";
    }).join("");
  }

  function onEvent(e) {
    live.events.push(e);
    if (e.lat != null && e.lon != null) {
      L.circleMarker([e.lat, e.lon], {radius: 6, color: "#fff", weight: 1.5, fillOpacity: 0.9,
                                      fillColor: LEVEL[e.level] || "#37474f"})
        .bindPopup(window.AlphaFence.popupHtml({title: e.event, popup: [["UTC", e.utc],
          ["", eventText(e)]]})).addTo(eventMarks);
    }
    drawEvents();
  }

  function onVehicle(v) {
    var first = !live.vehicle;
    live.vehicle = v;
    live.positions += 1;
    var here = L.latLng(v.lat, v.lon);
    marker.setLatLng(here).setIcon(arrow(v.heading_deg, LEVEL[v.level] || "#333"));
    if (!map.hasLayer(marker)) marker.addTo(map);
    track.addLatLng(here);
    var pts = track.getLatLngs();
    if (pts.length > TRACK_MAX) track.setLatLngs(pts.slice(-TRACK_MAX));
    path.setLatLngs(v.path);
    stop.setLatLng(v.stop);
    if (!map.hasLayer(prediction)) prediction.addTo(map);
    if (first) map.setView(here, 16);
    else if (!map.getBounds().pad(-0.15).contains(here)) map.panTo(here);
    drawStatus();
  }

  function onTraffic(m) {
    traffic.clearLayers();
    live.traffic = m.aircraft.length;
    m.aircraft.forEach(function (a) {
      var color = a.conflict ? "#b71c1c" : "#00838f";
      L.circle([a.lat, a.lon], {radius: a.radius_m, color: color, weight: 1.5,
                                fillOpacity: a.conflict ? 0.2 : 0.06}).addTo(traffic);
      L.marker([a.lat, a.lon], {icon: arrow(a.heading_deg, color)})
        .bindPopup(window.AlphaFence.popupHtml({title: a.callsign || a.key, popup: [
          ["altitude", fmt(a.alt_amsl_m, " m AMSL")], ["speed", fmt(a.speed_mps, " m/s")],
          ["protection", a.radius_m + " m, \u00b1" + a.half_height_m + " m"],
          ["conflict", a.conflict ? "yes" : "no"]]})).addTo(traffic);
    });
  }

  var handlers = {
    hello: function (m) { live.events = []; m.events.forEach(onEvent); },
    vehicle: onVehicle,
    fences: function (m) {
      fences.clearLayers();
      fences.addData(m.geojson);
      live.fences = m.geojson.features.length;
      live.fencesTotal = m.total;
      if (!live.vehicle) map.setView(m.center, 15);
    },
    onboard: function (m) {
      onboard.clearLayers();
      onboard.addData(m.geojson);
      live.onboard = m.geojson.features.length;
      live.onboardCause = m.cause;
    },
    traffic: onTraffic,
    basemap: function (m) {
      basemap.clearLayers();
      basemap.addData(m.geojson);
      if (!map.hasLayer(basemap)) basemap.addTo(map);
      basemap.bringToBack();
      live.basemap = m.geojson.features.length;
      if (m.attribution) map.attributionControl.addAttribution(m.attribution);
    },
    event: function (m) { onEvent(m.event); },
    dropped: function (m) { live.dropped = m.messages; drawStatus(); }
  };

  function connect() {
    var scheme = location.protocol === "https:" ? "wss://" : "ws://";
    var ws = new WebSocket(scheme + location.host + "/ws" + location.search);
    ws.onopen = function () { live.connected = true; drawStatus(); };
    ws.onmessage = function (msg) {
      var m = JSON.parse(msg.data);
      if (handlers[m.type]) handlers[m.type](m);
    };
    ws.onclose = function () {
      live.connected = false;
      drawStatus();
      setTimeout(connect, 1000);  // the monitor may be restarting
    };
  }
  drawStatus();
  drawEvents();
  connect();
})();
