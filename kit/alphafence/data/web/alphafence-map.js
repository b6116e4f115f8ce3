/* AlphaFence map: draws the layers of the page's data (the JSON in #af-data) with Leaflet.
 *
 * Data: {title, note, bounds: [[south, west], [north, east]], tiles: {url | data, attribution},
 *        layers: [{name, color, weight, dash, fill, radius, legend, ramp, hidden, features}]}
 * Each feature is GeoJSON (lon, lat); its properties may hold `color` (overrides the layer's),
 * `radius_m` (a Point drawn as a circle of that radius), `title` and `popup` ([[label, value]]).
 *
 * For other pages (and tests): window.AlphaFence = {createMap, addLayers, addLegend,
 * Graticule, popupHtml}; once drawn, window.afMap (the L.Map), window.afLayers (name -> layer)
 * and window.afReady (ms from navigation start to the first drawn frame).
 */
(function () {
  "use strict";

  function esc(text) {
    return String(text).replace(/[&<>"']/g, function (c) {
      return {"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;"}[c];
    });
  }

  function popupHtml(props) {
    var rows = (props.popup || []).map(function (row) {
      return "<tr><td>" + esc(row[0]) + "</td><td>" + esc(row[1]) + "</td></tr>";
    });
    var head = props.title ? '<div class="af-title">' + esc(props.title) + "</div>" : "";
    return '<div class="af-popup">' + head + "<table>" + rows.join("") + "</table></div>";
  }

  // A lat/lon grid: about six lines across the view at a round step, labelled at the edges.
  var STEPS = [];
  [-6, -5, -4, -3, -2, -1, 0, 1].forEach(function (e) {
    [1, 2, 5].forEach(function (m) { STEPS.push(m * Math.pow(10, e)); });
  });

  function decimals(step) {
    return Math.max(0, -Math.floor(Math.log10(step) + 1e-9));
  }

  function label(value, step, pos, neg) {
    var d = decimals(step);
    return Math.abs(value).toFixed(d) + "\u00b0" + (value < 0 ? neg : pos);
  }

  var Graticule = L.LayerGroup.extend({
    options: {color: "#607d8b", weight: 0.6, opacity: 0.6, lines: 6},

    onAdd: function (map) {
      L.LayerGroup.prototype.onAdd.call(this, map);
      map.on("moveend", this._draw, this);
      this._draw();
    },

    onRemove: function (map) {
      map.off("moveend", this._draw, this);
      L.LayerGroup.prototype.onRemove.call(this, map);
    },

    step: function () {
      var b = this._map.getBounds();
      var span = Math.max(b.getNorth() - b.getSouth(), b.getEast() - b.getWest());
      var want = span / this.options.lines;
      for (var i = 0; i < STEPS.length; i++) {
        if (STEPS[i] >= want) return STEPS[i];
      }
      return STEPS[STEPS.length - 1];
    },

    _draw: function () {
      this.clearLayers();
      var map = this._map;
      if (!map) return;
      var b = map.getBounds(), step = this.step(), o = this.options;
      var s = Math.max(b.getSouth(), -85), n = Math.min(b.getNorth(), 85);
      var w = Math.max(b.getWest(), -180), e = Math.min(b.getEast(), 180);
      var line = {color: o.color, weight: o.weight, opacity: o.opacity, interactive: false};
      var lat, lon, k;
      for (k = Math.ceil(s / step); k * step <= n; k++) {
        lat = k * step;
        this.addLayer(L.polyline([[lat, w], [lat, e]], line));
        this._label([lat, w], label(lat, step, "N", "S"), [0, 12]);
      }
      for (k = Math.ceil(w / step); k * step <= e; k++) {
        lon = k * step;
        this.addLayer(L.polyline([[s, lon], [n, lon]], line));
        this._label([n, lon], label(lon, step, "E", "W"), [-3, -2]);
      }
    },

    _label: function (latlng, text, anchor) {
      var icon = L.divIcon({className: "af-grid-label", html: esc(text), iconSize: null,
                            iconAnchor: anchor});
      this.addLayer(L.marker(latlng, {icon: icon, interactive: false, keyboard: false}));
    }
  });

  function styleOf(spec) {
    return function (feature) {
      var p = feature.properties || {};
      var color = p.color || spec.color || "#333";
      var geom = feature.geometry || {};
      if (geom.type === "Point" && p.radius_m == null) {  // a marker: filled, white rim
        return {color: "#fff", weight: 1.5, fill: true, fillColor: color, fillOpacity: 0.9,
                opacity: 1};
      }
      return {
        color: color,
        weight: spec.weight || 1.5,
        dashArray: spec.dash || null,
        fill: spec.fill != null && spec.fill > 0,
        fillColor: color,
        fillOpacity: spec.fill || 0,
        opacity: 0.9
      };
    };
  }

  function layerOf(spec) {
    var style = styleOf(spec);
    var group = L.geoJSON({type: "FeatureCollection", features: spec.features || []}, {
      style: style,
      pointToLayer: function (feature, latlng) {
        var s = style(feature), p = feature.properties || {};
        if (p.radius_m != null) return L.circle(latlng, L.extend(s, {radius: p.radius_m}));
        return L.circleMarker(latlng, L.extend(s, {radius: p.radius || spec.radius || 6}));
      }
    });
    // one popup binding for the whole layer: its text is made when a shape is clicked
    group.bindPopup(function (layer) { return popupHtml(layer.feature.properties || {}); },
                    {maxWidth: 360});
    return group;
  }

  function createMap(element, data) {
    var map = L.map(element, {preferCanvas: true, zoomSnap: 0.25, maxZoom: 21});
    map.attributionControl.setPrefix("Leaflet");
    var tiles = data.tiles;
    if (tiles && tiles.url) {
      L.tileLayer(tiles.url, {attribution: esc(tiles.attribution || ""), maxZoom: 19}).addTo(map);
    } else if (tiles && tiles.data) {
      var Held = L.GridLayer.extend({
        createTile: function (c) {
          var img = document.createElement("img");
          var uri = tiles.data[c.z + "/" + c.x + "/" + c.y];
          if (uri) img.src = uri;
          return img;
        }
      });
      new Held({attribution: esc(tiles.attribution || ""), minZoom: 0, maxZoom: 19}).addTo(map);
    }
    if (data.note) map.attributionControl.addAttribution(esc(data.note));
    L.control.scale({metric: true, imperial: false, maxWidth: 160}).addTo(map);
    return map;
  }

  function addLayers(map, specs) {
    var named = {}, overlays = {};
    specs.forEach(function (spec) {
      if (!spec.features || !spec.features.length) return;  // only what is there is listed
      var layer = layerOf(spec);
      if (!spec.hidden) layer.addTo(map);
      named[spec.name] = layer;
      overlays[esc(spec.name)] = layer;
    });
    // kept on the map: a live page adds its own overlays to it (control.addOverlay)
    map.afControl = L.control.layers(null, overlays, {collapsed: false, position: "topright"});
    map.afControl.addTo(map);
    return named;
  }

  function legendRow(spec) {
    if (spec.ramp) {
      var r = spec.ramp;
      return '<div class="af-row"><span>' + esc(spec.legend || spec.name) + " " +
        esc(r.low) + '</span><span class="af-ramp" style="background:linear-gradient(to right,' +
        r.colors.map(esc).join(",") + ')"></span><span>' + esc(r.high) + "</span></div>";
    }
    var rows = spec.legend_rows || [[spec.legend || spec.name, spec.color]];
    var marker = (spec.features || []).every(function (f) {
      return f.geometry && f.geometry.type === "Point" && (f.properties || {}).radius_m == null;
    });
    return rows.map(function (row) {
      var style = marker ?
        "width:10px;height:10px;border-radius:50%;border:1px solid #fff;background:" + row[1] :
        "border-color:" + row[1] + ";border-style:" + (spec.dash ? "dashed" : "solid") +
        ";background:" + (spec.fill ? row[1] + "40" : "transparent");
      return '<div class="af-row"><span class="af-swatch" style="' + esc(style) +
        '"></span><span>' + esc(row[0]) + "</span></div>";
    }).join("");
  }

  function addLegend(map, data) {
    var present = (data.layers || []).filter(function (s) {
      return s.features && s.features.length;
    });
    var legend = L.control({position: "bottomright"});
    legend.onAdd = function () {
      var div = L.DomUtil.create("div", "af-legend");
      div.innerHTML = (data.title ? '<div class="af-title">' + esc(data.title) + "</div>" : "") +
        present.map(legendRow).join("") +
        (data.legend_note ? '<div class="af-note">' + esc(data.legend_note) + "</div>" : "");
      L.DomEvent.disableClickPropagation(div);
      return div;
    };
    legend.addTo(map);
    return legend;
  }

  function fit(map, data, named) {
    if (data.bounds) {
      map.fitBounds(data.bounds, {padding: [12, 12]});
      return;
    }
    var bounds = L.latLngBounds([]);
    Object.keys(named).forEach(function (k) {
      var b = named[k].getBounds && named[k].getBounds();
      if (b && b.isValid()) bounds.extend(b);
    });
    if (bounds.isValid()) map.fitBounds(bounds, {padding: [12, 12], maxZoom: 18});
    else map.setView([0, 0], 2);
  }

  window.AlphaFence = {createMap: createMap, addLayers: addLayers, addLegend: addLegend,
                       Graticule: Graticule, popupHtml: popupHtml, fit: fit};

  var source = document.getElementById("af-data");
  if (!source || !document.getElementById("map")) return;  // another page using the parts
  var data = JSON.parse(source.textContent);
  var map = createMap("map", data);
  var named = addLayers(map, data.layers || []);
  fit(map, data, named);
  window.afGrid = new Graticule().addTo(map);
  addLegend(map, data);
  window.afMap = map;
  window.afLayers = named;
  requestAnimationFrame(function () {
    requestAnimationFrame(function () { window.afReady = performance.now(); });
  });
})();
