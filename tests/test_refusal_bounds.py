"""Refused values are quoted cut short in every error message; the numbers a launch takes have bounds
that mean something; a password has one length limit everywhere (API, forms, the user service)."""

from __future__ import annotations

import io
import json
import re

import pytest

from core.formats import FormatError, rle_to_mask
from core.wording import SHOWN_CHARS, quoted
from dataset.db import transaction
from dataset.export import parse_split_spec
from dataset.services import exports as export_service
from dataset.services import training
from dataset.services import users as user_service
from dataset.services.errors import FieldError, InvalidInput
from model.runs.schema import MIN_LR, RunLaunch, validate
from tests.conftest import login
from webapp.runtime import Runtime

LONG = "s" * 200_000


def bearer(tokens: dict[str, str], role: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {tokens[role]}"}


def assert_cut_short(message: str) -> None:
    """The message quotes a value of some 200000 characters (LONG and a few more) cut short."""
    assert len(message) < 400 and re.search(r"…\(2000\d\d characters\)", message), message[:400]


# --- refused values, quoted cut short ------------------------------------------------------------

def test_a_quoted_value_is_cut_short_with_its_length() -> None:
    assert quoted("ghost") == "'ghost'" and quoted(7) == "7"
    text = quoted(LONG)
    assert text.startswith("'sss") and text.endswith("…(200000 characters)") and len(text) < SHOWN_CHARS + 30


@pytest.mark.parametrize("field", ["source", "illusion_type"])
def test_an_upload_echoes_no_refused_value_whole(client, tokens, runtime, field) -> None:  # type: ignore[no-untyped-def]
    answer = client.post("/api/v1/videos", headers=bearer(tokens, "curator"), content_type="multipart/form-data",
                         data={"file": (io.BytesIO(b"RIFF" + b"\0" * 60), "clip.mp4"), field: LONG})
    assert answer.status_code == 400
    assert_cut_short(answer.json["error"])
    assert not list(runtime.media.root.rglob("*.mp4"))


def test_query_and_body_values_are_cut_short(client, tokens) -> None:  # type: ignore[no-untyped-def]
    state = client.get(f"/api/v1/frames?state={LONG}", headers=bearer(tokens, "annotator"))
    assert state.status_code == 400
    assert_cut_short(state.json["error"])
    number = client.post("/api/v1/prefilter", headers=bearer(tokens, "curator"), content_type="application/json",
                         data='{"video_id": 1' + "0" * 199_996 + "e400}")
    assert number.status_code == 400 and "out of range" in number.json["error"]
    assert_cut_short(number.json["error"])


def test_a_masks_size_is_cut_short() -> None:
    with pytest.raises(FormatError) as refused:
        rle_to_mask({"size": [int("9" * 4000), 1], "counts": "0"}, (4, 4))
    assert len(str(refused.value)) < 250 and "(4000 characters)" in str(refused.value)


def test_an_exports_split_is_cut_short(runtime: Runtime) -> None:
    with transaction(runtime.sessions) as s:
        for split in (LONG, f"train=1,{LONG}=0"):
            with pytest.raises(FieldError) as refused:
                export_service.create_export(s, runtime.settings, None, format="native", split=split)
            assert_cut_short(str(refused.value))


# --- launch numbers ------------------------------------------------------------------------------

@pytest.mark.parametrize("lr", [5e-324, 1e-300, MIN_LR / 2, 0.0])
def test_a_learning_rate_too_small_to_mean_anything_is_refused(lr: float) -> None:
    with pytest.raises(FieldError, match=re.escape(f"must be at least {MIN_LR}")) as refused:
        validate(RunLaunch, {"lr": lr})
    assert refused.value.field == "lr"


def test_the_smallest_learning_rate_and_a_split_without_a_test_share_are_taken() -> None:
    assert validate(RunLaunch, {"lr": MIN_LR}).lr == MIN_LR
    launch = validate(RunLaunch, {"split": "train=0.9,val=0.1,test=0"})
    assert training.parse_split(launch.split) == {"train": 0.9, "val": 0.1, "test": 0.0}
    assert parse_split_spec("train=1,test=0") == {"train": 1.0}  # an empty split is none
    assert parse_split_spec("train=0.99,test=0.01") == {"train": 0.99, "test": 0.01}


@pytest.mark.parametrize("split", ["train=1e-300,val=1", "train=0.995,val=0.005", "train=0.9,val=0.1,test=1e-9",
                                   "train=1.1,val=-0.1"])
def test_a_split_fraction_is_zero_or_at_least_a_percent(split: str) -> None:
    with pytest.raises(FieldError, match="0 or at least 0.01") as refused:
        validate(RunLaunch, {"split": split})
    assert refused.value.field == "split"


def test_an_exports_split_has_the_same_bound(runtime: Runtime) -> None:
    with transaction(runtime.sessions) as s, pytest.raises(FieldError, match="0 or at least 0.01"):
        export_service.create_export(s, runtime.settings, None, format="native", split="train=0.9999,test=0.0001")


def test_the_api_refuses_them(client, tokens) -> None:  # type: ignore[no-untyped-def]
    for body, field in (({"lr": 5e-324}, "lr"), ({"split": "train=1e-300,val=1"}, "split")):
        answer = client.post("/api/v1/runs", json=body, headers=bearer(tokens, "admin"))
        assert answer.status_code == 400 and answer.json["field"] == field, answer.json


# --- one password limit --------------------------------------------------------------------------

def test_one_password_limit_in_the_api_and_the_user_service(client, tokens, runtime) -> None:  # type: ignore[no-untyped-def]
    longest = "p" * user_service.MAX_PASSWORD
    made = client.post("/api/v1/users", headers=bearer(tokens, "admin"),
                       json={"name": "longest", "role": "annotator", "password": longest})
    assert made.status_code == 201, made.json
    over = client.post("/api/v1/users", headers=bearer(tokens, "admin"),
                       json={"name": "longer", "role": "annotator", "password": longest + "p"})
    assert over.status_code == 400 and f"at most {user_service.MAX_PASSWORD} characters" in over.json["error"]
    with transaction(runtime.sessions) as s:
        user = user_service.get_user(s, "longest")
        user_service.reset_password(s, None, user, longest)
        with pytest.raises(InvalidInput, match=f"at most {user_service.MAX_PASSWORD}"):
            user_service.reset_password(s, None, user, longest + "p")


def test_every_password_field_of_the_pages_takes_the_same_limit(client) -> None:  # type: ignore[no-untyped-def]
    fields = re.compile(r'<input[^>]*type="password"[^>]*>')
    for page in (client.get("/login").get_data(as_text=True),
                 (login(client, "admin"), client.get("/admin/users").get_data(as_text=True))[1]):
        inputs = fields.findall(page)
        assert inputs and all(f'maxlength="{user_service.MAX_PASSWORD}"' in i for i in inputs), inputs


def test_the_create_user_form_refuses_a_longer_password_itself(app, client) -> None:  # type: ignore[no-untyped-def]
    from webapp.forms import CreateUserForm

    with app.test_request_context(method="POST", data={"name": "n", "role": "annotator",
                                                       "password": "p" * (user_service.MAX_PASSWORD + 1)}):
        app.config["WTF_CSRF_ENABLED"] = False
        form = CreateUserForm()
        assert not form.validate() and form.password.errors


def test_the_openapi_document_publishes_the_bounds(client, tokens) -> None:  # type: ignore[no-untyped-def]
    schemas = client.get("/api/v1/openapi.json", headers=bearer(tokens, "annotator")).json["components"]["schemas"]
    assert schemas["RunLaunch"]["properties"]["lr"]["anyOf"][0]["minimum"] == MIN_LR
    password = schemas["NewUser"]["properties"]["password"]
    assert (password["minLength"], password["maxLength"]) == (user_service.MIN_PASSWORD, user_service.MAX_PASSWORD)
    assert json.dumps(schemas)  # plain JSON
