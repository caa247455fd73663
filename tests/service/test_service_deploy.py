"""Deployment files checked against what the service needs (no Docker engine here: parse and compare)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import tomllib
import zenoh

from service.cli import build_parser
from service.settings import ServiceSettings, load_settings

yaml = pytest.importorskip("yaml")
ROOT = Path(__file__).resolve().parents[2]
COMPOSE = yaml.safe_load((ROOT / "docker-compose.yml").read_text())
SERVICES = COMPOSE["services"]
_INTERP = re.compile(r"\$\{([A-Z_]+)(?::?-([^}]*))?\}")


def resolve(value: str) -> str:
    """Compose-style ${VAR:-default} with the default (tests never read the host environment)."""
    return _INTERP.sub(lambda m: m.group(2) or "", str(value))


def published(service: dict) -> list[tuple[str, str, str]]:
    """(host address, host port, container port) of each short-syntax ``ports`` entry; "" = all interfaces."""
    out = []
    for entry in service.get("ports", []):
        parts = str(entry).rsplit(":", 2)
        host_ip, host_port, container = parts if len(parts) == 3 else ("", *parts)
        out.append((host_ip, host_port, container))
    return out


def test_router_is_official_image_with_existing_config():
    router = SERVICES["zenoh-router"]
    assert router["image"].startswith("eclipse/zenoh:")
    for vol in router["volumes"]:
        src, dst = vol.split(":")[:2]
        assert (ROOT / src).is_file(), src
        assert dst in router["command"]
    conf = zenoh.Config.from_file(str(ROOT / "deploy/zenoh-router.json5"))  # Zenoh itself accepts it
    assert json.loads(conf.get_json("mode")) == "router"
    listen = json.loads(conf.get_json("listen/endpoints"))
    ports = {p.split(":")[-1] for p in listen}
    assert {container for _, _, container in published(router)} <= {*ports}


def test_service_env_names_exist_and_values_are_valid(monkeypatch, tmp_path):
    svc = SERVICES["aslm"]
    env = {k: resolve(v) for k, v in svc["environment"].items()}
    fields = {f"ASLM_{name.upper()}" for name in ServiceSettings.model_fields} | {"ASLM_CONFIG"}
    assert set(env) <= fields, set(env) - fields
    # The settings file the container mounts is the one in the repo, and it is valid with this environment.
    mounts = dict(v.split(":")[:2][::-1] for v in svc["volumes"] if v.startswith("./"))
    config_src = mounts[env["ASLM_CONFIG"]]
    assert (ROOT / config_src).is_file()
    tomllib.loads((ROOT / config_src).read_text())
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    monkeypatch.setenv("ASLM_CONFIG", str(ROOT / config_src))
    monkeypatch.setenv("ASLM_STORAGE_URL", str(tmp_path / "x.sqlite"))
    s = load_settings()
    # REST port published, Zenoh endpoint pointing at the router's service name and port.
    assert ("127.0.0.1", str(s.http_port), str(s.http_port)) in published(svc) and s.http_host == "0.0.0.0"
    router_port = published(SERVICES["zenoh-router"])[0][2]
    assert s.zenoh_connect == [f"tcp/zenoh-router:{router_port}"] and s.zenoh_mode == "client"
    assert any(v.split(":")[1] == "/data" for v in svc["volumes"]) and s.storage_path.parent == tmp_path
    assert svc["command"][0] in build_parser()._subparsers._group_actions[0].choices
    assert (ROOT / svc["build"]["context"] / svc["build"]["dockerfile"]).is_file()


def test_dask_profile_matches_executor_setting():
    sched, worker = SERVICES["dask-scheduler"], SERVICES["dask-worker"]
    assert sched["profiles"] == worker["profiles"] == ["dask", "cluster"]
    address = "tcp://dask-scheduler:8786"
    assert address in worker["entrypoint"] and "8786" in sched["expose"]
    assert "ports" not in sched  # the scheduler runs what it is sent: never published on the host
    assert sched["environment"]["DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES"] == "1"
    assert load_settings(executor=address, storage_url=":memory:").executor == address


def test_dask_containers_get_the_executors_cluster_config():
    """Dask reads the compose variables as the executor's CLUSTER_CONFIG (parsed by Dask itself)."""
    dask = pytest.importorskip("dask")
    from service.executors.dask import CLUSTER_CONFIG

    for name in ("dask-scheduler", "dask-worker"):
        env = {k: resolve(v) for k, v in SERVICES[name]["environment"].items()}
        with dask.config.set(dask.config.collect_env(env)):
            assert {key: dask.config.get(key, None) for key in CLUSTER_CONFIG} == CLUSTER_CONFIG, name


def test_published_ports_bind_loopback_only_and_never_the_dask_scheduler():
    # Issue 17, defect 7: "7447:7447" published the plain-TCP router (no access control) and "8786:8786"
    # the Dask scheduler (runs any code it is sent) on every host interface.
    for name, svc in SERVICES.items():
        for host_ip, host_port, _ in published(svc):
            assert host_ip == "127.0.0.1", f"{name} publishes {host_port} on all interfaces"
    assert "ports" not in SERVICES["dask-scheduler"] and "ports" not in SERVICES["dask-worker"]
    assert "network_mode" not in SERVICES["dask-scheduler"]  # host networking would expose it as well


def test_cluster_profile_runs_two_sharded_instances_on_the_dask_cluster(tmp_path):
    first, second = SERVICES["aslm"], SERVICES["aslm-2"]
    assert second["profiles"] == ["cluster"] and "dask-scheduler" in second["depends_on"]
    env = {k: resolve(v) for k, v in second["environment"].items()}
    s = load_settings(**{k[5:].lower(): json.loads(v) if v.startswith("[") else v
                         for k, v in env.items() if k not in ("ASLM_CONFIG", "ASLM_OPERATOR_TOKEN")}
                      | {"storage_url": str(tmp_path / "x.sqlite")})
    assert s.sources == ["zenoh-sharded"] and s.executor == "tcp://dask-scheduler:8786" and "zenoh" in s.sinks
    # Distinct, fixed instance names and host ports; the first instance is sharded through its environment.
    assert first["environment"]["ASLM_INSTANCE"] != s.instance
    assert {p[1] for p in published(first)}.isdisjoint(p[1] for p in published(second))
    assert "ASLM_SOURCES" in first["environment"]


def test_replayer_command_parses_and_targets_the_router():
    rep = SERVICES["replayer"]
    args = build_parser().parse_args(rep["command"])
    assert args.command == "replay" and args.connect == ["tcp/zenoh-router:7447"]


def test_dockerfile_copies_existing_paths():
    text = (ROOT / "deploy/Dockerfile").read_text()
    for line in text.splitlines():
        if line.startswith("COPY "):
            for src in line.split()[1:-1]:
                assert list(ROOT.glob(src.rstrip("*"))) or src.endswith("*"), src
    assert 'ENTRYPOINT ["aslm"]' in text
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "aslm" in project["project"]["scripts"]
    # The image installs every package the project lists (the replayer needs aslm_sim): each is copied in.
    for pkg in project["tool"]["setuptools"]["packages"]["find"]["include"]:
        assert f"COPY {pkg.rstrip('*')} " in text, pkg
