"""Records where users look: REST ``?format=…``, the ``records`` sink on ``{prefix}/records/{format}/{bus}`` and
``aslm export``; each payload states its assumptions."""

from __future__ import annotations

import json

from test_service_api import View, rest  # noqa: F401 - the REST fixture and its view

from aslm_core.records import Assumptions
from service.cli import main
from service.models import BusResult
from service.sinks import SINKS
from service.sinks.records import RecordsSink

D = {"a": 22.796, "b": 19.159, "H2": 1.0, "Tm": 0.2}
ZIP = {"Pz": 0.06, "Pi": 0.045, "Pp": 0.045, "Qz": 1.3105, "Qi": 0.03, "Qp": 0.03}


def _ok(bus: str, period: float, dynamic: dict | None = None) -> BusResult:
    params = {"dynamic": dynamic or D, "static": ZIP, "objective": 0.1, "fit": {"fd_p": 0.99, "fd_q": 0.99},
              "stderr": {"a": 0.3, "b": 0.2, "H2": 0.01, "Tm": 0.002}}
    return BusResult(bus=bus, period=period, period_s=10.0, status="ok", completed_at=period + 0.5, parameters=params)


def test_rest_serves_records_of_the_latest_and_of_history(rest):  # noqa: F811
    view, chain, client = rest
    chain.write_results([_ok("bus-9", 1000.0)])
    chain.write_results([_ok("bus-9", 1010.0)])
    plain = client.get("/buses/bus-9/parameters/latest")
    assert plain.json()["parameters"]["dynamic"] == D  # without format: the parameters, unchanged
    got = client.get("/buses/bus-9/parameters/latest", params={"format": "psse", "xp": 0.15, "loading": 0.7})
    assert got.status_code == 200, got.text
    body = got.json()
    assert body["bus"] == "bus-9" and body["period"] == 1010.0 and body["format"] == "psse"
    assert body["assumptions"]["xp"] == 0.15 and body["assumptions"]["loading"] == 0.7
    assert body["assumptions"]["f0"] == view.settings.f0
    assert "9 'CIM5BL' 'M'" in body["content"]
    bad = client.get("/buses/bus-9/parameters/latest", params={"format": "pslf", "xp": 5.0})
    assert bad.status_code == 422 and "admissible interval" in bad.json()["detail"]
    assert client.get("/buses/bus-9/parameters/latest", params={"format": "matpower"}).status_code == 422
    hist = client.get("/buses/bus-9/parameters", params={"format": "andes", "since": 1000.0, "until": 1000.0}).json()
    assert [(h["period"], h["format"]) for h in hist] == [(1000.0, "andes")]
    assert json.loads(hist[0]["content"])["Motor3"][0]["c1"] == D["Tm"]


def test_records_sink_publishes_every_format_with_its_assumptions():
    puts = []
    sink = RecordsSink(lambda k, p: puts.append((k, json.loads(p))), "aslm", Assumptions(f0=60.0))
    skipped = BusResult(bus="b3", period=1000.0, period_s=10.0, status="skipped", reason="gaps", completed_at=1.0)
    no_motor = _ok("b2", 1000.0, {**D, "Tm": 0.0})
    sink.write_results([_ok("b1", 1000.0), no_motor, skipped], ["", "", ""])
    keys = [k for k, _ in puts]
    assert keys == [f"aslm/records/{f}/{b}" for b in ("b1", "b2") for f in ("andes", "psse", "pslf")]
    first = dict(puts)["aslm/records/pslf/b1"]
    assert first["assumptions"]["f0"] == 60.0 and first["assumptions"]["free"] == "xp"
    assert first["content"].splitlines()[-1].startswith('motorw 1 "b1"')
    assert "carries no load" in dict(puts)["aslm/records/andes/b2"]["error"]
    assert SINKS["records"] == "service.sinks.records:build"


def test_aslm_export_writes_records_and_refuses_clearly(tmp_path, capsys):
    path = tmp_path / "r.json"
    path.write_text(json.dumps({"file": "x.npz", "dynamic": D, "static": ZIP}))
    assert main(["export", str(path), "--format", "pslf", "--f0", "60", "--xp", "0.18", "--bus-number", "9"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[-1].startswith('motorw 9 "ASLM" 138 "M "') and '"lp" 0.18' in out
    assert main(["export", str(path), "--format", "andes", "--json", "--loading", "0.5"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["assumptions"]["loading"] == 0.5 and payload["values"]["motor_mva"] == 40.0
    assert main(["export", str(path), "--format", "psse", "--td0", "0.01"]) == 1
    assert "Td0 > 1/b" in capsys.readouterr().err
    skipped = tmp_path / "s.json"
    skipped.write_text(BusResult(bus="b", period=1.0, period_s=10.0, status="skipped", reason="gaps",
                                 completed_at=1.0).model_dump_json())
    assert main(["export", str(skipped), "--format", "psse"]) == 1
    assert "no parameters to write" in capsys.readouterr().err
