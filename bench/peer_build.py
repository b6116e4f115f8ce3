"""The named peer of ``alphafence build`` as a whole process: pyosmium reads the extract's
areas whose tags a restriction rule names, and the ``alphashape`` package draws each one's alpha
shape at a fixed radius (no automatic alpha, no sites, margins or warning layers) in UTM metres
(pyproj), written as one GeoJSON FeatureCollection. Run as its own process by
:mod:`bench.cli_bench`; it imports nothing of AlphaFence, so its start is its own.

python bench/peer_build.py EXTRACT.osm.pbf OUT.geojson TAGS.json RADIUS_M
(TAGS.json: ``{"key": ["value", ...] or null}``, null for any value)
"""

from __future__ import annotations

import json
import sys


def main(argv):
    """Read, draw and write; exit status 0."""
    import alphashape
    import osmium
    import pyproj
    import shapely

    extract, out, tags_file, radius = argv[0], argv[1], argv[2], float(argv[3])
    with open(tags_file) as f:
        tags = {k: (None if v is None else set(v)) for k, v in json.load(f).items()}
    rings = []

    class Areas(osmium.SimpleHandler):
        def area(self, a):
            if any(k in a.tags and (v is None or a.tags[k] in v) for k, v in tags.items()):
                for outer in a.outer_rings():
                    rings.append([(n.lon, n.lat) for n in outer])

    Areas().apply_file(extract, locations=True)
    lon0 = sum(r[0][0] for r in rings) / max(1, len(rings))
    lat0 = sum(r[0][1] for r in rings) / max(1, len(rings))
    zone = int((lon0 + 180) // 6) + 1
    utm = pyproj.CRS.from_dict({"proj": "utm", "zone": zone, "south": lat0 < 0})
    fwd = pyproj.Transformer.from_crs("EPSG:4326", utm, always_xy=True)
    back = pyproj.Transformer.from_crs(utm, "EPSG:4326", always_xy=True)
    features = []
    for ring in rings:
        xs, ys = fwd.transform([p[0] for p in ring], [p[1] for p in ring])
        shape = alphashape.alphashape(list(zip(xs, ys)), 1.0 / radius)
        shape = shapely.transform(shape, lambda c: list(zip(*back.transform(c[:, 0], c[:, 1]))))
        features.append(
            {"type": "Feature", "properties": {}, "geometry": shapely.geometry.mapping(shape)}
        )
    with open(out, "w") as f:
        json.dump({"type": "FeatureCollection", "features": features}, f)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
