"""A compiled onboard plan signed by ``compile --sign-key`` uploads with ``--trusted-key``;
a plan changed after signing, or one never signed, is refused before anything is sent."""

import asyncio
import json

import pytest

from alphafence.cli import main
from alphafence.cli.demo import scene_path
from alphafence.fencefiles.qgc_plan import read_plan_geofence
from tests.fake_vehicle import FakeVehicle

BOX = "--bbox=-0.58,51.42,-0.52,51.44"


@pytest.fixture(scope="module")
def signed(tmp_path_factory):
    """Keys, the demo scene's fences, and a plan compiled from them and signed."""
    d = tmp_path_factory.mktemp("signed")
    priv, pub = d / "key.pem", d / "key.pub.pem"
    assert main(["bundle", "keygen", "--private", str(priv), "--public", str(pub)]) == 0
    fences = d / "fences.geojson"
    assert main(["build", str(scene_path()), "-o", str(fences), "-q"]) == 0
    plan = d / "onboard.plan"
    argv = ["compile", str(fences), BOX, "-o", str(plan), "--sign-key", str(priv)]
    assert main(argv) == 0
    return d, plan, pub, fences, priv


def upload(plan, *extra):
    async def run():
        async with FakeVehicle() as fake:
            argv = ["upload", str(plan), "--connect", fake.url, "--link", "pymavlink", *extra]
            code = await asyncio.to_thread(main, argv)
            return code, list(fake.fence), fake.received("MISSION_COUNT")

    return asyncio.run(run())


def one_error(capsys) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_compile_signs_the_plan_beside_it(signed, capsys):
    d, plan, pub, _, _ = signed
    sig = json.loads((d / "onboard.plan.sig.json").read_text())
    assert sig["file"] == "onboard.plan" and sig["algorithm"] == "ed25519"
    assert main(["bundle", "verify", str(plan), "--trusted-key", str(pub)]) == 0


def test_a_signed_plan_uploads_with_its_trusted_key(signed, capsys):
    _, plan, pub, _, _ = signed
    code, held, _ = upload(plan, "--trusted-key", str(pub))
    assert code == 0, capsys.readouterr()
    planned = read_plan_geofence(plan).upload_items
    assert [(i.command, i.x, i.y) for i in held] == [
        (i.command, round(i.lat * 1e7), round(i.lon * 1e7)) for i in planned
    ]
    assert "unverified" not in capsys.readouterr().err


def test_a_plan_changed_after_signing_is_refused(signed, tmp_path, capsys):
    d, plan, pub, _, _ = signed
    changed = tmp_path / "onboard.plan"
    doc = json.loads(plan.read_text())
    doc["geoFence"]["polygons"][0]["polygon"][0][0] += 0.001
    changed.write_text(json.dumps(doc))
    (tmp_path / "onboard.plan.sig.json").write_bytes((d / "onboard.plan.sig.json").read_bytes())
    code, held, counts = upload(changed, "--trusted-key", str(pub))
    assert code == 2 and not counts and not held
    line = one_error(capsys)
    assert str(changed) in line and "changed after they were signed" in line


def test_an_unsigned_plan_needs_allow_unsigned(signed, tmp_path, capsys):
    _, _, pub, fences, _ = signed
    plan = tmp_path / "onboard.plan"
    assert main(["compile", str(fences), BOX, "-o", str(plan)]) == 0
    capsys.readouterr()
    code, held, counts = upload(plan, "--trusted-key", str(pub))
    assert code == 2 and not counts
    assert "not signed" in one_error(capsys)
    code, held, _ = upload(plan, "--allow-unsigned")
    assert code == 0 and held


def test_a_bad_signing_key_writes_nothing(signed, tmp_path, capsys):
    _, _, pub, fences, _ = signed
    plan = tmp_path / "onboard.plan"
    argv = ["compile", str(fences), BOX, "-o", str(plan), "--sign-key", str(pub)]
    assert main(argv) == 2
    assert "private key" in one_error(capsys)
    assert list(tmp_path.iterdir()) == []
