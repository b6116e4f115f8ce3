"""The OGC API - Features client against a real pygeoapi over a real PostGIS table (both on
loopback), made to misbehave by a proxy (``tests/fault_proxy.py``): every failure a user can
meet is one line, and a failure after the first page gives an incomplete answer, never a
complete one."""

from __future__ import annotations

import socket

import pytest

from alphafence.errors import SourceError
from alphafence.sources.answers import read_zones
from alphafence.sources.ogc import SourceOptions, fetch, read_token, session
from tests.fault_proxy import FaultProxy
from tests.live_servers import clear_zones, ed318_zone, insert_zone

BOX = (14.40, 35.80, 14.60, 36.00)


def square(lon, lat, d=0.001):
    return [(lon, lat), (lon + d, lat), (lon + d, lat + d), (lon, lat + d), (lon, lat)]


@pytest.fixture
def zones(shared_source):
    """The shared table holding 25 zones inside BOX and 5 outside it."""
    pg, api, table = shared_source
    clear_zones(pg, table)
    for k in range(25):
        insert_zone(pg, table, ed318_zone(f"IN-{k}", square(14.45 + 0.004 * k, 35.9)))
    for k in range(5):
        insert_zone(pg, table, ed318_zone(f"OUT-{k}", square(15.0 + 0.004 * k, 36.5)))
    return shared_source


@pytest.fixture
async def proxy(zones):
    _, api, _ = zones
    p = await FaultProxy(api.url).start()
    yield p
    await p.stop()


async def ask(url, bbox=BOX, **kw):
    options = SourceOptions(url, **{"limit": 10, "retries": 1, "backoff_s": 0.01, **kw})
    async with session(options) as http:
        return await fetch(http, options, bbox)


async def test_every_page_is_read_and_only_the_area_asked(zones, rules):
    _, api, _ = zones
    answer = await ask(api.collection)
    assert answer.complete and answer.pages == 3, answer
    ids = sorted(f["id"] for f in answer.features)
    assert ids == sorted(f"IN-{k}" for k in range(25))
    found, bad = read_zones(answer.url, answer.features, rules)
    assert not bad and {z.id for z in found} == set(ids)
    assert all(z.restricted and z.restricted[0].rule.kind == "keep_out" for z in found)
    everything = await ask(api.collection, bbox=None)
    assert len(everything.features) == 30 and everything.complete


async def test_an_unchanged_source_answers_not_modified(proxy):
    proxy.fault = {"etag": True}
    options = SourceOptions(f"{proxy.url}/collections/zones", limit=100)
    async with session(options) as http:
        first = await fetch(http, options, BOX)
        again = await fetch(http, options, BOX, etag=first.etag)
    assert first.etag and not first.not_modified and len(first.features) == 25
    assert again.not_modified and again.features is None and again.complete
    changed = dict(proxy.fault, extra_features=[ed318_zone("NEW", square(14.5, 35.95))])
    proxy.fault = changed
    async with session(options) as http:
        third = await fetch(http, options, BOX, etag=first.etag)
    assert not third.not_modified and len(third.features) == 26  # a change is never missed


async def test_a_failed_later_page_makes_an_incomplete_answer(proxy):
    proxy.fault = {"fail_from_page": 2}
    answer = await ask(f"{proxy.url}/collections/zones")
    assert not answer.complete and len(answer.features) == 10
    assert "HTTP 503" in str(answer.error) and "after 2 tries" in str(answer.error)


def _closed_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize(
    "fault, expected",
    [
        ({"status": 500}, "HTTP 500: server error (after 2 tries)"),
        ({"token": "right"}, "HTTP 401: the token is missing, expired or wrong"),
        ({"status": 403}, "HTTP 403: the token is not allowed"),
        ({"html": True}, "answer is not GeoJSON (content type text/html)"),
        ({"truncate": True}, "answer is not JSON (cut short or malformed)"),
        ({"pad_bytes": 3_000_000}, "answer larger than 2 MiB: not read"),
        ({"delay_s": 3.0}, "no answer within 0.5 s (after 2 tries)"),
    ],
    ids=["500", "401", "403", "html", "truncated", "oversized", "slow"],
)
async def test_each_fault_is_one_line(proxy, fault, expected):
    proxy.fault = fault
    timeout_s = 0.5 if "delay_s" in fault else 30.0  # pygeoapi under a loaded suite: > 0.5 s
    with pytest.raises(SourceError) as err:
        await ask(f"{proxy.url}/collections/zones", max_bytes=2 * 2**20, timeout_s=timeout_s)
    assert expected in str(err.value) and "\n" not in str(err.value)
    assert str(err.value).startswith(f"{proxy.url}/collections/zones/items")


async def test_a_token_is_sent_as_a_bearer(proxy, tmp_path, monkeypatch):
    proxy.fault = {"token": "s3cret"}
    (tmp_path / "token").write_text("s3cret\n")
    answer = await ask(f"{proxy.url}/collections/zones", token=read_token(tmp_path / "token"))
    assert answer.complete and len(answer.features) == 25
    monkeypatch.setenv("ALPHAFENCE_SOURCE_TOKEN", "from-env")
    assert read_token() == "from-env"
    with pytest.raises(SourceError, match="cannot read the token file"):
        read_token(tmp_path / "missing")


async def test_no_such_collection_refused_and_unresolvable(zones):
    _, api, _ = zones
    with pytest.raises(SourceError, match="HTTP 404: no such collection"):
        await ask(f"{api.url}/collections/nothing")
    port = _closed_port()
    with pytest.raises(SourceError, match="connection refused by 127.0.0.1:.*is the server"):
        await ask(f"http://127.0.0.1:{port}/collections/zones")
    with pytest.raises(SourceError, match="cannot resolve host 'zones.invalid'"):
        await ask("http://zones.invalid/collections/zones")


async def test_the_server_clock_is_read_from_its_date(proxy):
    proxy.fault = {"date_offset_s": 600.0}
    answer = await ask(f"{proxy.url}/collections/zones")
    assert 590.0 < answer.server_skew_s < 610.0


async def test_malformed_features_are_named_and_the_good_ones_kept(proxy, rules):
    bad = {"type": "Feature", "id": "BAD-1", "geometry": {"type": "Polygon", "coordinates": [[[14.5, 35.9]]]},
           "properties": {"identifier": "BAD-1", "type": "PROHIBITED", "zoneAuthority": []}}  # fmt: skip
    untyped = ed318_zone("BAD-2", square(14.5, 35.95))
    del untyped["properties"]["type"]
    proxy.fault = {"extra_features": [bad, untyped]}
    answer = await ask(f"{proxy.url}/collections/zones", limit=100)
    found, lines = read_zones(answer.url, answer.features, rules)
    assert len(found) == 25, lines
    assert (
        len(lines) == 2 and "zone BAD-1" in lines[0] and "zone BAD-2: missing zone type" in lines[1]
    )


def _certificates(folder):
    """A CA and a server certificate for 127.0.0.1 it signed: (CA PEM path, server context)."""
    import datetime
    import ipaddress
    import ssl

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    now = datetime.datetime.now(datetime.timezone.utc)

    def cert(subject, issuer, key, signer, ca):
        b = (x509.CertificateBuilder().subject_name(subject).issuer_name(issuer)
             .public_key(key.public_key()).serial_number(x509.random_serial_number())
             .not_valid_before(now - datetime.timedelta(days=1))
             .not_valid_after(now + datetime.timedelta(days=1))
             .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True))  # fmt: skip
        if not ca:
            b = b.add_extension(
                x509.SubjectAlternativeName([x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]),
                critical=False,
            )
        return b.sign(signer, hashes.SHA256())

    ca_key, key = ec.generate_private_key(ec.SECP256R1()), ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "AlphaFence test CA")])
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "127.0.0.1")])
    ca = cert(ca_name, ca_name, ca_key, ca_key, True)
    server = cert(name, ca_name, key, ca_key, False)
    pem = serialization.Encoding.PEM
    (folder / "ca.pem").write_bytes(ca.public_bytes(pem))
    (folder / "server.pem").write_bytes(server.public_bytes(pem))
    (folder / "server.key").write_bytes(key.private_bytes(
        pem, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()))  # fmt: skip
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    context.load_cert_chain(folder / "server.pem", folder / "server.key")
    return folder / "ca.pem", context


async def test_tls_is_verified_and_a_ca_file_trusts_a_private_ca(zones, tmp_path):
    _, api, _ = zones
    ca, context = _certificates(tmp_path)
    proxy = await FaultProxy(api.url).start(ssl_context=context)
    try:
        url = f"{proxy.url}/collections/zones"
        assert url.startswith("https://")
        with pytest.raises(SourceError, match="TLS certificate of 127.0.0.1:.* not trusted"):
            await ask(url)
        answer = await ask(url, ca_file=str(ca))
        assert answer.complete and len(answer.features) == 25
        with pytest.raises(SourceError, match="cannot read the CA file"):
            await ask(url, ca_file=str(tmp_path / "missing.pem"))
    finally:
        await proxy.stop()
