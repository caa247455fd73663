"""The secure Zenoh router configuration in deploy/: Zenoh accepts it, and its access control does what
docs/security.md says (only bridges put frames, only service instances put results), on a real router
with mutual TLS on 127.0.0.1 and certificates made here with openssl."""

from __future__ import annotations

import json
import shutil
import subprocess
import threading
import time
from pathlib import Path

import pytest
import zenoh

ROOT = Path(__file__).resolve().parents[2]
SECURE = ROOT / "deploy" / "zenoh-router-secure.json5"
ROLES = ("aslm-bridge", "aslm-service", "aslm-consumer", "stranger")


def test_secure_router_config_is_valid_zenoh_and_closed_by_default():
    conf = zenoh.Config.from_file(str(SECURE))  # refuses unknown keys, rule messages and flows
    acl = json.loads(conf.get_json("access_control"))
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    tls = json.loads(conf.get_json("transport/link/tls"))
    assert tls["enable_mtls"] is True
    assert json.loads(conf.get_json("transport/link/protocols")) == ["tls"]
    assert all(e.startswith("tls/") for e in json.loads(conf.get_json("listen/endpoints")))
    rules = {r["id"]: r for r in acl["rules"]}
    subjects = {s["id"]: s["cert_common_names"] for s in acl["subjects"]}
    writes: dict[str, set[str]] = {}
    for policy in acl["policies"]:
        for rule in map(rules.get, policy["rules"]):
            if "put" in rule["messages"] and rule["flows"] == ["ingress"] and rule["permission"] == "allow":
                for subject in policy["subjects"]:
                    writes.setdefault(subject, set()).update(rule["key_exprs"])
    # Who may put where: bridges only frames, services only results; consumers nothing.
    assert writes == {"bridges": {"aslm/pmu/**"},
                      "services": {"aslm/params/**", "aslm/diagnosis/**", "aslm/records/**"}}
    assert subjects == {"bridges": ["aslm-bridge"], "services": ["aslm-service"], "consumers": ["aslm-consumer"]}


def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True)


def _certificates(d: Path) -> None:
    """A private CA, the router's certificate for 127.0.0.1 and one client certificate per role."""
    _openssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out", "ca.pem",
             "-days", "2", "-subj", "/CN=aslm-test-ca", cwd=d)
    # X.509 v3 with extensions for every certificate: rustls refuses v1 certificates.
    (d / "router.ext").write_text("subjectAltName=IP:127.0.0.1,DNS:localhost\nextendedKeyUsage=serverAuth\n")
    (d / "client.ext").write_text("basicConstraints=CA:FALSE\nextendedKeyUsage=clientAuth\n")
    for name in ("router", *ROLES):
        _openssl("req", "-newkey", "rsa:2048", "-nodes", "-keyout", f"{name}.key", "-out", f"{name}.csr",
                 "-subj", f"/CN={'localhost' if name == 'router' else name}", cwd=d)
        _openssl("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
                 "-out", f"{name}.pem", "-days", "2", "-extfile", "router.ext" if name == "router" else "client.ext",
                 cwd=d)


def _client(d: Path, role: str, endpoint: str) -> zenoh.Session:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("transport/link/tls", json.dumps({
        "root_ca_certificate": str(d / "ca.pem"), "enable_mtls": True,
        "connect_certificate": str(d / f"{role}.pem"), "connect_private_key": str(d / f"{role}.key")}))
    return zenoh.open(conf)


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs openssl to make the test certificates")
def test_only_bridges_put_frames_and_only_services_put_results(tmp_path):
    _certificates(tmp_path)
    with __import__("socket").socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    endpoint = f"tls/127.0.0.1:{port}"
    conf = zenoh.Config.from_file(str(SECURE))  # the deployed rules, with this test's files and port
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    for key, name in (("root_ca_certificate", "ca.pem"), ("listen_certificate", "router.pem"),
                      ("listen_private_key", "router.key")):
        conf.insert_json5(f"transport/link/tls/{key}", json.dumps(str(tmp_path / name)))
    router = zenoh.open(conf)
    # Publishers and listeners are separate sessions: a session's own puts reach its own subscribers
    # without crossing the router, so the ACL would not see them.
    sessions = {role: _client(tmp_path, role, endpoint) for role in ROLES}
    listeners = {who: _client(tmp_path, role, endpoint) for who, role in
                 (("service", "aslm-service"), ("consumer", "aslm-consumer"), ("stranger", "stranger"))}
    got: dict[str, list[str]] = {"service": [], "consumer": [], "stranger": []}
    lock = threading.Lock()

    def keep(who: str):
        def cb(sample) -> None:
            with lock:
                got[who].append(f"{sample.key_expr}={sample.payload.to_string()}")
        return cb

    try:
        subs = [listeners["service"].declare_subscriber("aslm/pmu/**", keep("service")),
                listeners["consumer"].declare_subscriber("aslm/params/**", keep("consumer")),
                listeners["stranger"].declare_subscriber("aslm/**", keep("stranger"))]
        time.sleep(1.0)  # subscriptions propagate to the router
        for role, session in sessions.items():
            session.put("aslm/pmu/b1", role)
            session.put("aslm/params/b1", role)
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and not (got["service"] and got["consumer"]):
            time.sleep(0.1)
        time.sleep(1.0)  # anything denied would have arrived by now too
        with lock:
            assert got["service"] == ["aslm/pmu/b1=aslm-bridge"]
            assert got["consumer"] == ["aslm/params/b1=aslm-service"]
            assert got["stranger"] == []  # a valid certificate with an unknown CN receives nothing
        del subs
    finally:
        for session in (*sessions.values(), *listeners.values()):
            session.close()
        router.close()
