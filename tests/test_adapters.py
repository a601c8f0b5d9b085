"""The adapter registry and contract."""

from __future__ import annotations

from importlib.metadata import EntryPoint
from typing import Any

import numpy as np
import pytest

from rtp import sdk
from rtp.sdk import adapters


class FakeAdapter(adapters.Adapter):
    name = "fake"
    supported_channels = frozenset({"reprojected.r", "seen", "albedo.r", "normal.z"})

    def inputs(self, frame: Any) -> Any:  # the contract itself: tests/test_adapter_contract.py
        return np.zeros((len(self.channels), self.height, self.width), np.float32)

    def close(self) -> None:
        pass


@pytest.fixture
def clean_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(adapters, "_registered", {})
    monkeypatch.setattr(adapters, "_discovered", None)


def test_register_and_get(clean_registry: None) -> None:
    adapters.register("fake", FakeAdapter)
    assert adapters.get("fake") is FakeAdapter
    assert "fake" in adapters.available()


def test_unknown_name_lists_what_is_available(clean_registry: None) -> None:
    adapters.register("fake", FakeAdapter)
    with pytest.raises(adapters.AdapterNotFoundError, match="available: .*fake") as info:
        adapters.get("unreal")
    assert isinstance(info.value, LookupError) and isinstance(info.value, sdk.RtpError)
    assert "did you mean" not in str(info.value)
    with pytest.raises(adapters.AdapterNotFoundError, match=r"no adapter named 'fak' \(did you mean fake\?\); available"):
        adapters.get("fak")


def _installed(monkeypatch: pytest.MonkeyPatch, *declared: tuple[str, str]) -> None:
    """Installed packages' adapter entry points, as ``(name, "module:Class")`` in the order found."""
    eps = [EntryPoint(name, target, adapters.ENTRY_POINT_GROUP) for name, target in declared]

    def fake_entry_points(group: str) -> list[Any]:
        return [e for e in eps if e.group == group]

    monkeypatch.setattr(adapters, "entry_points", fake_entry_points)


def test_entry_point_discovery_dedupes_and_survives_a_broken_plugin(
    clean_registry: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    _installed(monkeypatch, ("fake", "tests.test_adapters:FakeAdapter"), ("fake", "tests.test_adapters:FakeAdapter"),
               ("broken", "no_such_module_for_rtp:Adapter"), ("typo", "tests.test_adapters:NoSuchAdapter"),
               ("ownextra", "rtp.plugins.no_such_plugin:Adapter"))
    assert adapters.available() == ["broken", "fake", "ownextra", "typo"]
    assert adapters.get("fake") is FakeAdapter
    # a third party's plugin is its package's to fix: the hint named an rtp extra, 'rtp[broken]', that does not
    # exist; only rtp's own plugins that cannot import are pointed to their extra
    for name, hint in (("broken", "the entry point 'no_such_module_for_rtp:Adapter' is its package's to fix"),
                       ("typo", "AttributeError"), ("ownextra", "is its extra installed? e.g. pip install 'rtp[ownextra]'")):
        with pytest.raises(adapters.AdapterNotFoundError, match="failed to load") as info:
            adapters.get(name)
        assert hint in str(info.value) and ("rtp[" in str(info.value)) == (name == "ownextra"), str(info.value)
    assert adapters.get("fake") is FakeAdapter  # the broken one did not spoil the rest


def test_adapter_refuses_channels_it_cannot_produce() -> None:
    a = FakeAdapter(sdk.DEFAULT_INPUTS, 16, 16)
    assert a.channels == sdk.DEFAULT_INPUTS
    with pytest.raises(adapters.UnsupportedChannelError, match="cannot produce motion.x"):
        FakeAdapter(["seen", "motion.x"], 16, 16)
    with pytest.raises(adapters.UnsupportedChannelError, match="unknown channel"):
        FakeAdapter(["colour"], 16, 16)


def test_an_adapter_without_a_frame_source_says_so() -> None:
    with pytest.raises(adapters.NoFrameSourceError, match="fake adapter provides no frame source") as err:
        FakeAdapter.frame_source(None, 8, 8)
    assert isinstance(err.value, NotImplementedError) and isinstance(err.value, sdk.RtpError)


class OtherFakeAdapter(FakeAdapter):
    pass


def test_two_packages_declaring_one_name_are_not_chosen_between_in_silence(
    clean_registry: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    # two installed packages declaring "fake" (a fork beside the original): get() loaded whichever entry point came
    # first on sys.path, in silence; the same target listed twice (an editable install) is still one
    _installed(monkeypatch, ("fake", "tests.test_adapters:FakeAdapter"), ("fake", "tests.test_adapters:OtherFakeAdapter"),
               ("fake", "tests.test_adapters:FakeAdapter"), ("solo", "tests.test_adapters:FakeAdapter"))
    assert adapters.available() == ["fake", "solo"]
    with pytest.raises(adapters.AdapterNotFoundError, match=r"adapter 'fake' is declared by 2 installed entry points: "
                       r"'tests.test_adapters:FakeAdapter', 'tests.test_adapters:OtherFakeAdapter'; uninstall all but "
                       r"one package, or choose one with sdk.adapters.register\('fake', ...\)"):
        adapters.get("fake")
    assert adapters.get("solo") is FakeAdapter
    adapters.register("fake", OtherFakeAdapter)  # the explicit choice
    assert adapters.get("fake") is OtherFakeAdapter


def test_a_name_that_is_not_a_string_says_what_was_expected(clean_registry: None) -> None:
    adapters.register("fake", FakeAdapter)
    for bad in (None, ["fake"], FakeAdapter):  # (a list was a bare TypeError: unhashable type)
        with pytest.raises(adapters.AdapterNotFoundError, match=r"expected an adapter's name \(a string such as "
                           r"'moderngl'\), got .*; available: fake"):
            adapters.get(bad)  # type: ignore[arg-type]
