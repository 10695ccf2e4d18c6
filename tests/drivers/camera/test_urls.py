"""Camera URLs: the registry, each backend's forms and options, Aravis errors as typed errors.
None of this needs a camera or Aravis."""

import pytest

from drivers.camera import FORMS, UnsupportedError, camera_class, open_camera
from drivers.camera.aravis_config import Settings, parse_aravis_url, translate
from drivers.errors import ConnectError, ConnectionLostError, DeviceError, RefusedError, UrlError


@pytest.mark.parametrize("url", ["gige://cam1", "cam1", "", "usb3://x"])
def test_unknown_scheme_lists_the_accepted_forms(url):
    with pytest.raises(UrlError) as err:
        camera_class(url)
    assert FORMS in str(err.value)


def test_registry_imports_lazily():
    assert camera_class("sim://p/left").__name__ == "SimCamera"
    assert camera_class("file:///x/*.png").__name__ == "FileReplayCamera"
    assert camera_class("opencv://0").__name__ == "OpenCvCamera"


@pytest.mark.parametrize("url,needle", [
    ("sim://pair1/middle", "expected sim://PAIR/left|right"),
    ("sim://pair1", "expected sim://PAIR/left|right"),
    ("sim://pair1/left?seed=-1", "seed must be >= 0"),
    ("sim://pair1/left?sede=1", "unknown option sede"),
    ("file:///tmp/x_*.png?loop=maybe", "option loop='maybe' is not valid"),
    ("file:///tmp/x_*.png?fps=3", "unknown option fps"),
    ("opencv://zero", "expected a camera index or a file path"),
    ("opencv://0?width=0", "option width='0' is not valid"),
    ("opencv://256", "the camera index 256 is not a /dev/videoN number (0-255)"),
    ("opencv://99999999999999999999", "is not a /dev/videoN number (0-255)"),
    ("aravis://?trigger=software", "expected aravis://DEVICE-ID"),
    ("aravis://cam?trigger=line", "option trigger='line' is not valid"),
    ("aravis://cam?pixel_format=Mono12", "option pixel_format='Mono12' is not valid"),
    ("aravis://cam?buffers=0", "option buffers='0' is not valid"),
    ("aravis://cam?region=1,2,3", "option region='1,2,3' is not valid"),
    ("aravis://cam?exposure=100", "unknown option exposure"),
    ("aravis://cam?heartbeat_ms=500", "a heartbeat timeout in milliseconds is 1500-600000"),
    ("aravis://cam?heartbeat_ms=3s", "heartbeat_ms"),
    ("aravis://cam?stream_socket=raw", "option stream_socket='raw' is not valid"),
])
def test_bad_urls_say_what_is_wrong(url, needle):
    with pytest.raises(UrlError) as err:
        open_camera(url)
    assert needle in str(err.value)


def test_aravis_url_keeps_the_device_id_as_written():
    s, timing = parse_aravis_url("aravis://Hikrobot-MV-CS200-10UC-DA1234567?trigger=Line1"
                                 "&pixel_format=bayerrg8&exposure_us=20000&gain_db=1.5"
                                 "&buffers=6&region=full&timeout=3&heartbeat_ms=10000"
                                 "&stream_socket=Packet")
    assert s == Settings("Hikrobot-MV-CS200-10UC-DA1234567", "line1", "BayerRG8", 20000.0, 1.5,
                         6, "full", heartbeat_ms=10000, stream_socket="packet")
    assert timing == {"timeout": 3.0}
    s, _ = parse_aravis_url("aravis://Vendor%20X-Model-1?region=0,0,5472,3648")
    assert s.name == "Vendor X-Model-1" and s.region == (0, 0, 5472, 3648)
    assert s.trigger == "software" and s.buffers == 4 and s.stream_socket == "udp"


class _GError(Exception):
    """What PyGObject raises: domain, code, message."""

    def __init__(self, domain, code, message):
        super().__init__(message)
        self.domain, self.code, self.message = domain, code, message


@pytest.mark.parametrize("domain,code,cls", [
    ("arv-device-error-quark", 5, ConnectionLostError),  # timeout: the GigE camera vanished
    ("arv-device-error-quark", 4, ConnectionLostError),  # transfer error: USB unplugged
    ("arv-device-error-quark", 6, ConnectionLostError),  # not found
    ("arv-device-error-quark", 18, ConnectError),  # busy: another program has control
    ("arv-device-error-quark", 1, UnsupportedError),  # feature not found
    ("arv-gc-error-quark", 8, RefusedError),  # enum entry not found
    ("arv-gc-error-quark", 4, RefusedError),  # out of range
    ("g-io-error-quark", 0, DeviceError),
])
def test_aravis_errors_become_typed_errors(domain, code, cls):
    exc = translate(_GError(domain, code, "[Feature] it failed"), "set feature", "aravis://x")
    assert type(exc) is cls and exc.code == code
    assert str(exc).startswith("aravis://x: set feature: [Feature] it failed")
