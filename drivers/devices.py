"""One way to build, check and open any device of the station from its URL.

Each kind keeps its own registry of backends (``drivers.camera``, ``drivers.lift``,
``drivers.wrench``: a scheme names a backend, imported only when used), but the station asks
through this one module: :func:`check_url` at ``config check``, start and reload (the device
is built, never opened: a URL that cannot work is a configuration error with its line),
:func:`open_device` when a device's keeper opens it; and what a device is, asked of its
backend's class rather than read from its scheme's name (:func:`simulated`,
:func:`world_view`; a controller's abilities: ``drivers.wrench.takes_targets``,
``takes_register_map``).  Every device it returns has the one
lifecycle of :class:`drivers.lifecycle.Openable` (``open``, ``reconnect``, ``close``) and
the typed interface of its kind (:class:`CameraDevice`, :class:`Lift`, :class:`Wrench`), so
the station's joins are typed, never ``Any``.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Any, Literal, overload

from drivers.camera import CameraDevice, camera_class, check_camera_url
from drivers.errors import UrlError
from drivers.lifecycle import Openable
from drivers.lift import Lift, RegisterMap, check_lift_url, lift_class
from drivers.wrench import Wrench, open_wrench, wrench_class


class Kind(StrEnum):
    """The kinds of device a station has."""

    CAMERA = "camera"
    LIFT = "lift"
    WRENCH = "wrench"


@overload
def build(kind: Literal[Kind.CAMERA], url: str, **options: Any) -> CameraDevice: ...
@overload
def build(kind: Literal[Kind.LIFT], url: str, **options: Any) -> Lift: ...
@overload
def build(kind: Literal[Kind.WRENCH], url: str, **options: Any) -> Wrench: ...
@overload
def build(kind: Kind, url: str, **options: Any) -> Openable: ...


def build(kind: Kind, url: str, **options: Any) -> Openable:
    """The device of ``url``, built and not opened: nothing connects, no simulator starts.
    ``options`` go to the backend (``timeout``; a lift's ``register_map``; a controller's
    register map or simulated psets); the URL's own options win.  UrlError when the URL
    names no backend of this kind or an option is out of range."""
    if kind is Kind.CAMERA:
        return camera_class(url)(url, **options)
    if kind is Kind.LIFT:
        register_map: RegisterMap | None = options.pop("register_map", None)
        return lift_class(url)(url, register_map, **options)
    return open_wrench(url, connect=False, **options)


def backend_class(kind: Kind, url: str) -> type[Openable]:
    """The backend class of ``url`` as a device of ``kind``, imported now and not built
    (UrlError when the URL names no backend of this kind)."""
    if kind is Kind.CAMERA:
        return camera_class(url)
    if kind is Kind.LIFT:
        return lift_class(url)
    return wrench_class(url)


def simulated(kind: Kind, url: str) -> bool:
    """Whether the device of ``url`` is a simulated twin (:attr:`Openable.simulated`), so a
    simulated world must run beside the station; False for a URL naming no backend."""
    try:
        return backend_class(kind, url).simulated
    except UrlError:
        return False


def world_view(url: str) -> tuple[str, str] | None:
    """The pair and side of the simulated world the camera at ``url`` shows (None: a camera
    of the real world, or a URL naming no camera backend; a UrlError for a simulated
    camera's malformed URL)."""
    try:
        cls = camera_class(url)
    except UrlError:
        return None
    return cls.world_view(url)


@overload
def open_device(kind: Literal[Kind.CAMERA], url: str, **options: Any) -> CameraDevice: ...
@overload
def open_device(kind: Literal[Kind.LIFT], url: str, **options: Any) -> Lift: ...
@overload
def open_device(kind: Literal[Kind.WRENCH], url: str, **options: Any) -> Wrench: ...
@overload
def open_device(kind: Kind, url: str, **options: Any) -> Openable: ...


def open_device(kind: Kind, url: str, **options: Any) -> Openable:
    """The device of ``url``, built and opened once (a DeviceError when it cannot be
    reached; what was built is closed again).  Close it, or use ``with``."""
    device = build(kind, url, **options)
    try:
        device.open()
    except BaseException:
        device.close()
        raise
    return device


def check_url(kind: Kind, url: str, *, sources: bool = False, **options: Any) -> None:
    """Check ``url`` as a device of ``kind`` without opening anything (UrlError): its
    scheme, form and options with their ranges; with ``sources`` (``config check``) also
    what it would read that exists now or never (a camera replay's files)."""
    if kind is Kind.CAMERA:
        check_camera_url(url, sources=sources)
    elif kind is Kind.LIFT:
        check_lift_url(url)
    else:
        try:
            build(kind, url, **options).close()
        except ValueError as exc:   # a backend's own refusal that is not a UrlError yet
            raise UrlError(str(exc), device=url) from None


__all__ = ["Kind", "backend_class", "build", "check_url", "open_device", "simulated",
           "world_view"]
