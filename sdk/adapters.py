"""Renderer adapters: the contract every adapter follows, and the registry that finds them by name.

An adapter turns one renderer's G-buffers and previous frame into a model's input tensor: float32
``(C, H, W)``, C-contiguous, top-left origin, channels in the order of ``metadata.inputs`` and with
the value conventions of :data:`rtp.sdk.CHANNELS`. Every adapter is driven the same way::

    from rtp import sdk
    Adapter = sdk.adapters.get("moderngl")      # entry point "moderngl" in group "rtp.adapters"
    with Adapter.for_predictor(predictor, width, height, **engine_objects) as adapter:
        x = adapter.inputs(frame)               # frame: the adapter's own frame type (Adapter.frame_type)
        rates = predictor.shading_rates(x)

What a frame holds belongs to the engine (textures and matrices, a scene and two poses, ...): the
adapter declares its type as :attr:`Adapter.frame_type`. A caller that does not know the engine gets
frames, and the adapter that reads them, from the adapter's :class:`FrameSource`::

    with Adapter.frame_source(scene, width, height) as source, source.adapter(channels) as adapter:
        x = adapter.inputs(source.frame(camera, prev_camera))

Installed packages declare adapters as entry points::

    [project.entry-points."rtp.adapters"]
    myengine = "myengine_rtp:Adapter"

Frozen applications and tests, where entry points may be missing, call :func:`register`. Discovery
is lazy (the first ``get``/``available``), deduplicated by name (an explicit ``register`` wins), and
a plugin that fails to import is logged and reported when asked for, without breaking the others.
"""

from __future__ import annotations

import abc
import difflib
import functools
import logging
import numbers
import threading
import weakref
from collections.abc import Callable, Iterable
from importlib.metadata import entry_points
from types import TracebackType
from typing import TYPE_CHECKING, Any, ClassVar, Generic, TypeVar

import numpy as np

from ._channels import CHANNELS
from ._errors import EXIT_USAGE, ParameterError, RtpError

if TYPE_CHECKING:
    from ._predictor import ShadingRatePredictor

__all__ = [
    "ENTRY_POINT_GROUP",
    "Adapter",
    "AdapterClosedError",
    "AdapterFrameError",
    "AdapterNotFoundError",
    "AdapterOutputError",
    "FrameSource",
    "NoFrameSourceError",
    "UnsupportedChannelError",
    "available",
    "get",
    "register",
]

log = logging.getLogger("rtp.sdk.adapters")

#: The entry-point group adapters are declared in.
ENTRY_POINT_GROUP = "rtp.adapters"

FrameT = TypeVar("FrameT")
_ClosableT = TypeVar("_ClosableT", bound="_Closable")
_AdapterT = TypeVar("_AdapterT", bound="Adapter[Any]")


class AdapterNotFoundError(RtpError, LookupError):
    """No adapter of that name is registered or installed (or its plugin failed to import)."""

    exit_code = EXIT_USAGE


class UnsupportedChannelError(RtpError, ValueError):
    """A model asks for an input channel the adapter cannot produce honestly."""

    exit_code = EXIT_USAGE


class AdapterClosedError(RtpError, RuntimeError):
    """An adapter or frame source was used after :meth:`~Adapter.close`."""


class AdapterFrameError(RtpError, TypeError):
    """:meth:`Adapter.inputs` was given a frame that is not of the adapter's :attr:`~Adapter.frame_type`,
    or an adapter an engine object of the wrong type (the moderngl adapter's ``ctx``)."""

    exit_code = EXIT_USAGE


class NoFrameSourceError(RtpError, NotImplementedError):
    """The adapter cannot draw frames itself (:meth:`Adapter.frame_source`): an engine adapter whose
    frames only the engine makes. Every adapter rtp registers has one."""


class AdapterOutputError(RtpError, RuntimeError):
    """An adapter broke the contract: its ``inputs`` returned something other than a C-contiguous
    float32 ``(C, H, W)`` array with one plane per requested channel, or its constructor (or its frame
    source's) did not call ``super().__init__`` (a bug in the adapter)."""


# --------------------------------------------------------------------------------------------- lifecycle
_OPEN, _CLOSING, _CLOSED = "open", "closing", "closed"


def _guard_close(fn: Callable[[Any], None]) -> Callable[[Any], None]:
    """Run a subclass's ``close`` once. An override that calls ``super().close()`` still runs the
    whole chain; later calls return at once. A ``close`` that raises still leaves the object closed
    (retrying could free the same resources twice)."""

    @functools.wraps(fn)
    def close(self: _Closable) -> None:
        state = self.__dict__.get("_rtp_state", _OPEN)
        if state == _CLOSED:
            return
        if state == _CLOSING:  # super().close() from an override: part of the one close
            fn(self)
            return
        self.__dict__["_rtp_state"] = _CLOSING
        try:
            try:
                self._close_dependents()
            finally:  # (an adapter whose close raised must not leave the engine itself unfreed)
                fn(self)
        finally:
            self.__dict__["_rtp_state"] = _CLOSED

    close._rtp_guarded = True  # type: ignore[attr-defined]
    return close


def _guard_init(fn: Callable[..., None]) -> Callable[..., None]:
    """Run a subclass's ``__init__``, then refuse an object whose ``__init__`` never reached the base's
    (``super().__init__(...)`` forgotten): it would fail later, at first use, with an ``AttributeError``
    naming a private attribute."""

    @functools.wraps(fn)
    def __init__(self: _Closable, *args: Any, **kwargs: Any) -> None:
        fn(self, *args, **kwargs)
        if "_rtp_state" not in self.__dict__:
            base = "Adapter" if isinstance(self, Adapter) else "FrameSource"
            params = "channels, width, height" if base == "Adapter" else "adapter_class, width, height"
            raise AdapterOutputError(
                f"{type(self).__qualname__}.__init__ did not call super().__init__({params}): every "
                f"rtp.sdk.adapters.{base} subclass calls it first (docs/adapters.md)"
            )

    __init__._rtp_guarded = True  # type: ignore[attr-defined]
    return __init__


def _guard_open(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Raise :class:`AdapterClosedError` instead of running ``fn`` after close."""

    @functools.wraps(fn)
    def method(self: _Closable, *args: Any, **kwargs: Any) -> Any:
        self._check_open()
        return fn(self, *args, **kwargs)

    method._rtp_guarded = True  # type: ignore[attr-defined]
    return method


class _Closable:
    """Shared lifecycle of adapters and frame sources: ``close`` runs once, the methods named in
    ``_open_only`` raise :class:`AdapterClosedError` after it, and ``with`` closes on exit.

    Subclasses write ``close`` (and their other methods) for the open state only: the base wraps
    every ``close`` a subclass defines, and every method named in ``_open_only``, when the subclass
    is created.
    """

    _open_only: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        init = cls.__dict__.get("__init__")
        if callable(init) and not getattr(init, "_rtp_guarded", False):
            setattr(cls, "__init__", _guard_init(init))  # noqa: B010 (mypy refuses assigning to a method)
        for name in ("close", *cls._open_only):
            fn = cls.__dict__.get(name)
            if not callable(fn) or getattr(fn, "__isabstractmethod__", False) or getattr(fn, "_rtp_guarded", False):
                continue
            setattr(cls, name, _guard_close(fn) if name == "close" else cls._guard(name, fn))

    @classmethod
    def _guard(cls, name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        return _guard_open(fn)

    def _describe(self) -> str:
        return type(self).__name__

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has been called."""
        return self.__dict__.get("_rtp_state", _OPEN) != _OPEN

    def _check_open(self) -> None:
        """Raise :class:`AdapterClosedError` if closed; call it at the top of extra public methods."""
        if self.closed:
            raise AdapterClosedError(f"this {self._describe()} has been closed; create a new one")

    def _close_dependents(self) -> None:
        """Close what must go before this object does (a frame source's adapters)."""

    @abc.abstractmethod
    def close(self) -> None:
        """Free the engine resources; idempotent (the base runs it once)."""

    def __enter__(self: _ClosableT) -> _ClosableT:
        self._check_open()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


# --------------------------------------------------------------------------------------------- adapter
class Adapter(_Closable, abc.ABC, Generic[FrameT]):
    """Base class of renderer adapters: the contract every adapter follows.

    A subclass sets :attr:`name`, :attr:`supported_channels` and :attr:`frame_type`, takes
    ``(channels, width, height, **engine_options)`` in its constructor and calls
    ``super().__init__(channels, width, height)`` first, and implements the two abstract methods:

    * :meth:`inputs` ``(frame) -> np.ndarray``: the model's input planes for one frame;
    * :meth:`close` ``()``: free what the adapter holds (GL objects, contexts, borrowed state).

    The base class supplies the rest, for every adapter alike: channel validation
    (:class:`UnsupportedChannelError` rather than zeros in place of a missing buffer), the
    :attr:`channels`, :attr:`width` and :attr:`height` properties, :meth:`frame_size` (the size of
    the planes of a frame: the adapter's, unless a subclass says a smaller one), :meth:`for_predictor`, the
    context manager, an idempotent :meth:`close`, :class:`AdapterClosedError` when :meth:`inputs`
    is called after close, :class:`AdapterFrameError` for a frame of the wrong type and
    :class:`AdapterOutputError` when an adapter returns something else than its contract says.
    An adapter also provides :meth:`frame_source`, through which generic callers (the contract
    tests, tools) obtain frames without knowing the engine.
    """

    #: Registry name (the entry-point name), e.g. ``"moderngl"``.
    name: ClassVar[str] = ""
    #: The channels (names of :data:`rtp.sdk.CHANNELS`) the adapter can produce.
    supported_channels: ClassVar[frozenset[str]] = frozenset()
    #: The type of the ``frame`` argument of :meth:`inputs` (what the engine hands over each frame).
    frame_type: ClassVar[type] = object

    def __init__(self, channels: Iterable[str], width: int, height: int) -> None:
        if isinstance(channels, str) or not isinstance(channels, Iterable):
            what = f"the string {channels!r}" if isinstance(channels, str) else type(channels).__name__
            raise UnsupportedChannelError(f"channels must be a sequence of channel names, got {what}")
        self._channels: tuple[str, ...] = tuple(channels)
        unknown = [c for c in self._channels if not isinstance(c, str) or c not in CHANNELS]  # ([] is unhashable)
        if unknown:
            raise UnsupportedChannelError(f"unknown channel {unknown[0]!r}; known channels: {', '.join(CHANNELS)}")
        missing = [c for c in self._channels if c not in self.supported_channels]
        if missing:
            raise UnsupportedChannelError(
                f"the {self.name or type(self).__name__} adapter cannot produce {', '.join(missing)}; it produces "
                f"{', '.join(c for c in CHANNELS if c in self.supported_channels)}"
            )
        if not self._channels:
            raise UnsupportedChannelError("no channels requested; pass the model's inputs (predictor.metadata.inputs)")
        if not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) and v >= 1 for v in (width, height)):
            raise ParameterError(f"frame size: expected positive integers (pixels), got {width!r} x {height!r}", "size")
        self._width, self._height = int(width), int(height)
        self.__dict__["_rtp_state"] = _OPEN

    @classmethod
    def for_predictor(
        cls: type[_AdapterT], predictor: ShadingRatePredictor, width: int, height: int, **options: Any
    ) -> _AdapterT:
        """The adapter producing ``predictor``'s inputs (``predictor.metadata.inputs``, in order) at
        ``width`` x ``height``; ``options`` are the adapter's own (its engine objects and settings)."""
        inputs = getattr(getattr(predictor, "metadata", None), "inputs", None)
        if inputs is None:
            raise AdapterFrameError(
                f"for_predictor needs a predictor (from sdk.load(...)), got {type(predictor).__name__}"
            )
        return cls(inputs, width, height, **options)

    @classmethod
    def frame_source(cls, scene: Any, width: int, height: int, **options: Any) -> FrameSource[FrameT]:
        """A :class:`FrameSource` drawing ``scene`` (an :class:`rtp.scene.Scene`) in this adapter's
        engine at ``width`` x ``height``: how a caller that does not know the engine obtains frames
        of :attr:`frame_type` and the adapter that reads them (``source.adapter(channels)``).

        Every registered adapter provides one (``tests/test_adapter_contract.py`` drives each
        through it); the base raises :class:`NoFrameSourceError`.
        """
        raise NoFrameSourceError(
            f"the {cls.name or cls.__name__} adapter provides no frame source; implement "
            "frame_source(scene, width, height) (docs/adapters.md)"
        )

    @property
    def channels(self) -> tuple[str, ...]:
        """The channels produced, in order (the planes of :meth:`inputs`)."""
        return self._channels

    @property
    def width(self) -> int:
        return self._width

    @property
    def height(self) -> int:
        return self._height

    def frame_size(self, frame: FrameT) -> tuple[int, int]:
        """``(width, height)`` of the planes :meth:`inputs` returns for ``frame``: the adapter's size. An
        adapter whose frames may say a smaller render resolution (dynamic resolution drawn into a corner of
        the engine's largest targets) overrides it to return that one."""
        return self._width, self._height

    @abc.abstractmethod
    def inputs(self, frame: FrameT) -> np.ndarray:
        """The model's input planes for ``frame``: float32 ``(C, H, W)``, C-contiguous, top-left
        origin, one plane per entry of :attr:`channels`, in that order, with the value conventions
        of :data:`rtp.sdk.CHANNELS`; ``(W, H)`` is :meth:`frame_size` (the adapter's size unless the
        frame says a smaller one). Raises :class:`AdapterClosedError` after :meth:`close`."""

    @abc.abstractmethod
    def close(self) -> None:
        """Free what the adapter holds. Runs once: later calls do nothing."""

    @classmethod
    def _guard(cls, name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        if name != "inputs":
            return _guard_open(fn)

        @functools.wraps(fn)
        def inputs(self: Adapter[Any], frame: Any, *args: Any, **kwargs: Any) -> np.ndarray:
            self._check_open()
            if not isinstance(frame, self.frame_type):
                raise AdapterFrameError(
                    f"the {self._describe()} reads {self.frame_type.__module__}.{self.frame_type.__qualname__} "
                    f"frames, got {type(frame).__module__}.{type(frame).__qualname__}"
                )
            x = fn(self, frame, *args, **kwargs)
            self._check_output(x, self.frame_size(frame))
            return x

        inputs._rtp_guarded = True  # type: ignore[attr-defined]
        return inputs

    _open_only: ClassVar[tuple[str, ...]] = ("inputs",)

    def _check_output(self, x: Any, size: tuple[int, int]) -> None:
        expected = (len(self._channels), size[1], size[0])
        if not isinstance(x, np.ndarray):
            problem = f"a {type(x).__name__}"
        elif x.dtype != np.float32:
            problem = f"dtype {x.dtype}"
        elif x.shape != expected:
            problem = f"shape {x.shape}"
        elif not x.flags.c_contiguous:
            problem = "a non-contiguous array"
        else:
            return
        raise AdapterOutputError(
            f"the {self._describe()} returned {problem} from inputs(); the contract is a C-contiguous float32 "
            f"array of shape (C, H, W) = {expected}"
        )

    def _describe(self) -> str:
        return f"{self.name or type(self).__name__} adapter"

    def __repr__(self) -> str:
        state = "closed" if self.closed else "open"
        return f"<{type(self).__qualname__} {self.name!r} {self._width}x{self._height} {list(self._channels)} {state}>"


# --------------------------------------------------------------------------------------------- frame source
class FrameSource(_Closable, abc.ABC, Generic[FrameT]):
    """An engine drawing a scene: where a caller that does not know the engine gets frames of an
    adapter's :attr:`~Adapter.frame_type`, and the adapter that reads them.

    Obtained from :meth:`Adapter.frame_source`. :meth:`frame` draws the previous and the current
    camera and returns what the engine would hand its adapter; :meth:`adapter` builds the adapter
    class with the engine objects it needs (:meth:`adapter_options`). Closing the source first
    closes the adapters it built, since they borrow its engine. A frame stays valid until the next
    :meth:`frame` call (its buffers may be reused, as an engine reuses its G-buffers).
    """

    _open_only: ClassVar[tuple[str, ...]] = ("frame",)

    def __init__(self, adapter_class: type[Adapter[FrameT]], width: int, height: int) -> None:
        if not isinstance(adapter_class, type) or not issubclass(adapter_class, Adapter):
            raise ParameterError(f"adapter_class: expected an rtp.sdk.adapters.Adapter subclass, got {adapter_class!r}",
                                 "adapter_class")
        if not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) and v >= 1 for v in (width, height)):
            raise ParameterError(f"frame size: expected positive integers (pixels), got {width!r} x {height!r}", "size")
        self._adapter_class = adapter_class
        self._width, self._height = int(width), int(height)
        self._adapters: list[weakref.ref[Adapter[FrameT]]] = []
        self.__dict__["_rtp_state"] = _OPEN

    @property
    def adapter_class(self) -> type[Adapter[FrameT]]:
        return self._adapter_class

    @property
    def width(self) -> int:
        return self._width

    @property
    def height(self) -> int:
        return self._height

    @abc.abstractmethod
    def frame(self, camera: Any, prev_camera: Any) -> FrameT:
        """Draw ``prev_camera`` (the previous displayed frame) and ``camera`` (the current one),
        both :class:`rtp.scene.Camera`, and return the current frame as the adapter reads it."""

    @abc.abstractmethod
    def close(self) -> None:
        """Free the engine. Runs once, after closing the adapters built by :meth:`adapter`."""

    def adapter_options(self) -> dict[str, Any]:
        """The engine objects the adapter needs (constructor keyword arguments); default none."""
        return {}

    def adapter(self, channels: Iterable[str], **options: Any) -> Adapter[FrameT]:
        """The adapter producing ``channels`` from this source's frames (``options`` override
        :meth:`adapter_options`)."""
        self._check_open()
        adapter = self._adapter_class(channels, self._width, self._height, **{**self.adapter_options(), **options})
        self._adapters = [r for r in self._adapters if r() is not None]
        self._adapters.append(weakref.ref(adapter))
        return adapter

    def _close_dependents(self) -> None:
        errors: list[Exception] = []
        for ref in self._adapters:  # every one, even after one whose close raised (then that error)
            adapter = ref()
            if adapter is not None:
                try:
                    adapter.close()
                except Exception as exc:
                    errors.append(exc)
        self._adapters = []
        if errors:
            raise errors[0]

    def _describe(self) -> str:
        return f"{self._adapter_class.name or self._adapter_class.__name__} frame source"


# --------------------------------------------------------------------------------------------- registry
_lock = threading.Lock()
_registered: dict[str, type[Adapter[Any]]] = {}
#: The entry points by name, each name's distinct targets in the order found (more than one: two installed
#: packages declare the same name, and neither is chosen in silence).
_discovered: dict[str, list[Any]] | None = None
_broken: dict[str, str] = {}


def _is_adapter_class(obj: Any) -> bool:
    return isinstance(obj, type) and issubclass(obj, Adapter)


def register(name: str, adapter: type[Adapter[Any]]) -> None:
    """Register an adapter class under ``name``; it takes precedence over entry points (and chooses
    between two installed packages that declare the same name). Registering another class under a
    registered name replaces it."""
    if not isinstance(name, str) or not name:
        raise ParameterError(f"adapter name must be a non-empty string, got {name!r}")
    if not _is_adapter_class(adapter):
        raise ParameterError(f"an adapter must be a subclass of rtp.sdk.adapters.Adapter, got {adapter!r}")
    with _lock:
        _registered[name] = adapter


def _discover() -> dict[str, list[Any]]:
    global _discovered
    with _lock:
        if _discovered is None:
            found: dict[str, list[Any]] = {}
            for ep in entry_points(group=ENTRY_POINT_GROUP):
                same = found.setdefault(ep.name, [])
                if all(other.value != ep.value for other in same):  # editable installs can list one twice
                    same.append(ep)
            _discovered = found
        return _discovered


def available() -> list[str]:
    """Names of the registered and installed adapters."""
    return sorted(set(_registered) | set(_discover()))


def get(name: str) -> type[Adapter[Any]]:
    """The adapter class registered or installed under ``name``."""
    if not isinstance(name, str):
        raise AdapterNotFoundError(f"expected an adapter's name (a string such as 'moderngl'), got "
                                   f"{type(name).__name__} {name!r}; available: {', '.join(available()) or 'none'}")
    if name in _registered:
        return _registered[name]
    eps = _discover()
    if name in eps and len(eps[name]) > 1:  # two packages claim the name: which one loads depended on sys.path
        _broken[name] = f"declared by {len(eps[name])} installed entry points: " + ", ".join(
            repr(ep.value) for ep in eps[name])
        raise AdapterNotFoundError(
            f"adapter {name!r} is {_broken[name]}; uninstall all but one package, or choose one with "
            f"sdk.adapters.register({name!r}, ...)"
        )
    if name in eps:
        ep = eps[name][0]
        try:
            obj = ep.load()
        except Exception as err:  # a broken plugin must not take the host down
            _broken[name] = f"{type(err).__name__}: {err}"
            log.warning("adapter plugin %r failed to load: %s", name, _broken[name])
            # rtp's own plugins miss their extra when they cannot import (pip install 'rtp[moderngl]'); a third
            # party's is its package's to fix (the rtp extra the hint named does not exist)
            own = str(ep.value).startswith("rtp.plugins.")
            hint = (f"is its extra installed? e.g. pip install 'rtp[{name}]'" if own and isinstance(err, ImportError)
                    else f"the entry point {ep.value!r} is its package's to fix or reinstall")
            raise AdapterNotFoundError(
                f"adapter {name!r} is installed but failed to load ({_broken[name]}); {hint}"
            ) from err
        if not _is_adapter_class(obj):
            _broken[name] = f"{ep.value} is not an rtp.sdk.adapters.Adapter subclass"
            log.warning("adapter plugin %r: %s", name, _broken[name])
            raise AdapterNotFoundError(f"adapter {name!r}: {_broken[name]}")
        with _lock:
            _registered[name] = obj
        return obj
    names = available()
    close = difflib.get_close_matches(name, names, n=1) if isinstance(name, str) else []
    raise AdapterNotFoundError(
        f"no adapter named {name!r}{f' (did you mean {close[0]}?)' if close else ''}; "
        f"available: {', '.join(names) if names else 'none'} "
        f"(install a plugin that declares it in the {ENTRY_POINT_GROUP!r} entry-point group, or call "
        f"sdk.adapters.register)"
    )
