"""``python -m bench`` writes its rows as JSON (``--out DIR``/results.json) beside its table."""

import json
import math
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIELDS = {
    "group": str,
    "name": str,
    "result": str,
    "value": (float, type(None)),
    "unit": (str, type(None)),
    "target": str,
    "peer": (str, type(None)),
    "peer_value": (float, type(None)),
    "ratio": (str, type(None)),
    "ok": bool,
}


def test_a_group_writes_its_rows_as_json(tmp_path):
    out = tmp_path / "nested" / "bench-out"
    run = subprocess.run(
        [sys.executable, "-m", "bench", "--osm", "unused.osm.pbf", "--only", "as-read"]
        + ["--out", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode in (0, 1), run.stderr
    assert "Traceback" not in run.stderr, run.stderr  # a crash is exit 1 too, and no table
    doc = json.loads((out / "results.json").read_text())
    assert doc["argv"][-2:] == ["--out", str(out)]
    assert len(doc["loadavg"]) == 2
    rows = doc["rows"]
    assert len(rows) >= 3
    for row in rows:
        assert set(row) == set(FIELDS), row
        for key, kind in FIELDS.items():
            assert isinstance(row[key], kind), (key, row)
        assert row["group"] == "as-read"
        assert row["name"] in run.stdout.replace("\n", " ") or row["name"][:30] in run.stdout
        for key in ("value", "peer_value"):
            assert row[key] is None or math.isfinite(row[key])
    assert [p.name for p in out.iterdir()] == ["results.json"]  # no temporary file left
    # the table's failures are the JSON's
    assert (run.returncode == 1) == (not all(r["ok"] for r in rows))
