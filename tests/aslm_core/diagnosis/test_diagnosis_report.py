"""The typed diagnosis report, its JSON and its REST mirror (service.models): same fields, same docs, valid."""

from __future__ import annotations

import dataclasses
import json
import typing

import numpy as np
import pytest
from conftest import equation_window
from pydantic import BaseModel, TypeAdapter

from aslm_core.diagnosis import DiagnosisReport, diagnose
from aslm_core.diagnosis import report as rp
from aslm_core.diagnosis.candidates import LIBRARY
from service import models
from service.api import create_app

# Every part of the report and its pydantic mirror.
MIRRORS: dict[type, type[BaseModel]] = {
    rp.PerChannel: models.PerChannelModel, rp.CandidateEntry: models.CandidateEntryModel,
    rp.NoiseFloor: models.NoiseFloorModel, rp.BandTest: models.BandTestModel,
    rp.CoherenceStat: models.CoherenceStatModel, rp.Coherence: models.CoherenceModel,
    rp.Location: models.LocationModel, rp.HeldOutFit: models.HeldOutFitModel,
    rp.NoiseSummary: models.NoiseSummaryModel, rp.HeldOutInfo: models.HeldOutInfoModel,
    rp.Motor: models.MotorModel, rp.Diagnosed: models.DiagnosedModel,
    rp.ParameterMismatch: models.ParameterMismatchModel, rp.DiagnosisReport: models.DiagnosisReportModel,
}


def _noisy(seed: int):
    """A 10 s window of the paper's equations with white measurement noise on P and Q (≈ 30 dB)."""
    w = equation_window(seed=seed)
    rng = np.random.default_rng(seed)
    P, Q = (x + rng.standard_normal(x.size) * 0.03 * np.std(x) for x in (w.P, w.Q))
    return dataclasses.replace(w, P=P, Q=Q)


@pytest.fixture(scope="module")
def reports() -> dict[str, DiagnosisReport]:
    w1, w2 = _noisy(3), _noisy(4)
    user = {"dynamic": {"a": 40.0, "b": 15.0, "H2": 1.3, "Tm": 1.2},
            "static": {"Pz": 2.0, "Pi": 1.0, "Pp": 3.0, "Qz": -1.0, "Qi": 0.5, "Qp": 1.0}}
    return {"one": diagnose(w1), "user": diagnose(w1, user), "two": diagnose([w1, w2])}


def test_every_part_has_its_mirror_with_the_same_fields_and_descriptions():
    parts = {t for t in vars(rp).values() if dataclasses.is_dataclass(t) and t.__module__ == rp.__name__}
    assert parts == set(MIRRORS)
    for dc, model in MIRRORS.items():
        own = [f.name for f in dataclasses.fields(dc) if f.metadata.get("json", True)]
        assert list(model.model_fields) == own, dc.__name__
        docs = rp.field_docs(dc)
        for name, info in model.model_fields.items():
            assert info.description == docs[name], (dc.__name__, name)
            # Optional in the JSON exactly where the dataclass has a default.
            f = next(f for f in dataclasses.fields(dc) if f.name == name)
            has_default = f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING
            assert info.is_required() is not has_default, (dc.__name__, name)


def test_nested_parts_are_mirrored_by_the_nested_models():
    for dc, model in MIRRORS.items():
        hints = typing.get_type_hints(dc)
        for name, info in model.model_fields.items():
            inner = {a for a in _leaves(hints[name]) if a in MIRRORS}
            assert {MIRRORS[a] for a in inner} == {a for a in _leaves(info.annotation) if a in MIRRORS.values()}, \
                (dc.__name__, name)


def _leaves(tp) -> set:
    args = typing.get_args(tp)
    return {tp} if not args else set().union(*(_leaves(a) for a in args))


def test_a_real_report_validates_and_every_entry_has_the_same_keys(reports):
    adapter = TypeAdapter(models.LatestDiagnosis)
    for kind, rep in reports.items():
        d = rep.to_dict()
        assert "series" not in d
        js = json.dumps({"bus": "eq", "period": 1.0e9, **d})
        got = adapter.validate_json(js)
        assert isinstance(got, models.BusDiagnosis), kind
        # The mirror loses nothing: dumped back it is the same JSON.
        assert json.loads(got.model_dump_json()) == json.loads(js), kind
        keys = {tuple(e) for e in d["missing_physics"]}
        assert keys == {tuple(f.name for f in dataclasses.fields(rp.CandidateEntry))}, kind
        assert [e["name"] for e in d["missing_physics"]] and {e["name"] for e in d["missing_physics"]} == set(LIBRARY)


def test_untested_candidates_carry_nulls_and_a_note(reports):
    # Against a re-identified ZIP the exponential static load is not testable (docs/diagnosis.md).
    e = reports["one"].candidate("exponential_static")
    assert not e.tested and e.note and e.penalised_gain is None and e.magnitude_z is None
    assert e.excess_reduction == rp.PerChannel(None, None) and e.improvement_band == rp.PerChannel(None, None)
    assert reports["one"].missing_physics[-1] is e
    assert reports["user"].candidate("exponential_static").tested


def test_report_parts_match_the_diagnosis_mode(reports):
    one, user, two = reports["one"], reports["user"], reports["two"]
    assert one.mode == one.model.mode == "identified" and one.parameter_mismatch is None
    assert user.mode == user.model.mode == "user"
    assert set(user.parameter_mismatch.reidentified.dynamic) == {"a", "b", "H2", "Tm"}
    assert one.located.windows is None and set(one.located.noise_floor) == {"P", "Q"}
    assert two.located.noise_floor is None and len(two.located.windows) == two.held_out.windows == 2
    # Cross-fitted by default: each window's time-ordered fold, then its mirrored one.
    assert one.held_out.windows == 1 and one.held_out.folds == 2 and len(one.held_out.t_start) == 2
    assert len(two.held_out.t_start) == two.held_out.windows * two.held_out.folds == 4
    assert two.held_out.t_start[0] > two.held_out.t_start[2] and two.held_out.t_start[1] > two.held_out.t_start[3]


def test_a_failed_diagnosis_as_the_service_stores_it_validates():
    payload = {"bus": "b1", "period": 1.0e9, "verdict": "failed", "reason": "timeout",
               "message": "no result within 120 s"}
    got = TypeAdapter(models.LatestDiagnosis).validate_python(payload)
    assert isinstance(got, models.FailedDiagnosis) and got.reason == "timeout"


def test_openapi_documents_the_diagnosis_payload():
    spec = create_app(None).openapi()  # the handlers are never called: no service needed
    ok = spec["paths"]["/buses/{bus}/diagnosis/latest"]["get"]["responses"]["200"]["content"]["application/json"]
    refs = {s["$ref"].rsplit("/", 1)[1] for s in ok["schema"]["oneOf"]}
    assert refs == {"BusDiagnosis", "FailedDiagnosis"}
    schemas = spec["components"]["schemas"]
    entry = schemas["CandidateEntryModel"]["properties"]
    assert entry["score_z"]["description"] == rp.field_docs(rp.CandidateEntry)["score_z"]
    assert set(schemas["BusDiagnosis"]["properties"]) >= {"verdict", "located", "missing_physics", "bus", "period"}
