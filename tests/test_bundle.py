"""Signed fence databases: only untouched fences signed by a trusted key verify."""

import json

import pytest

from alphafence.cli import main
from alphafence.cli.demo import scene_path
from alphafence.errors import InputError
from alphafence.fencing.bundle import generate_key, sign, signature_path, verify


@pytest.fixture
def signed(tmp_path):
    fences = tmp_path / "fences.geojson"
    assert main(["build", str(scene_path()), "-o", str(fences), "-q"]) == 0
    generate_key(tmp_path / "k.pem", tmp_path / "k.pub.pem")
    generate_key(tmp_path / "other.pem", tmp_path / "other.pub.pem")
    sign(fences, tmp_path / "k.pem")
    return fences, tmp_path


def test_signed_fences_verify_with_their_metadata(signed):
    fences, d = signed
    meta = verify(fences, [d / "k.pub.pem"])
    assert meta["tool"].startswith("alphafence") and meta["build"]["method"] == "alpha"
    assert (d / "k.pem").stat().st_mode & 0o077 == 0


@pytest.mark.parametrize(
    "attack, expected",
    [
        ("edit", "changed after they were signed"),
        ("other-key", "not trusted"),
        ("forged", "does not match its contents"),
        ("unsigned", "not signed"),
    ],
)
def test_tampering_is_refused(signed, attack, expected):
    fences, d = signed
    trusted = [d / "k.pub.pem"]
    if attack == "edit":
        fences.write_text(fences.read_text().replace('"keep_out"', '"warning"', 1))
    elif attack == "other-key":
        sign(fences, d / "other.pem")
    elif attack == "forged":
        doc = json.loads(signature_path(fences).read_text())
        doc["metadata"]["tool"] = "evil"
        signature_path(fences).write_text(json.dumps(doc))
    else:
        signature_path(fences).unlink()
    with pytest.raises(InputError, match=expected):
        verify(fences, trusted)


def test_cli_round_trip(tmp_path, capsys):
    fences = tmp_path / "f.geojson"
    assert main(["build", str(scene_path()), "-o", str(fences), "-q"]) == 0
    assert (
        main(
            [
                "bundle",
                "keygen",
                "--private",
                str(tmp_path / "k.pem"),
                "--public",
                str(tmp_path / "k.pub"),
            ]
        )
        == 0
    )
    assert main(["bundle", "sign", str(fences), "--key", str(tmp_path / "k.pem")]) == 0
    assert main(["bundle", "verify", str(fences), "--trusted-key", str(tmp_path / "k.pub")]) == 0
    assert "authentic" in capsys.readouterr().out
    assert (
        main(["bundle", "verify", str(fences), "--trusted-key", str(tmp_path / "k.pem")]) == 2
    )  # a private key


def test_upload_accepts_signed_fences_and_refuses_tampered_ones(signed, capsys):
    fences, d = signed
    base = ["upload", str(fences), "--bbox=-0.58,51.42,-0.52,51.44", "--dry-run"]
    assert main(base + ["--trusted-key", str(d / "k.pub.pem")]) == 0
    assert main(base + ["--trusted-key", str(d / "other.pub.pem")]) == 2
    assert "not trusted" in capsys.readouterr().err
    fences.write_text(fences.read_text().replace('"keep_out"', '"warning"', 1))
    assert main(base + ["--trusted-key", str(d / "k.pub.pem")]) == 2
    assert "changed after they were signed" in capsys.readouterr().err
