"""Two eyes from one head pose, and which eye a server frame is rendered for.

A headset shows two images: each eye sits half the interpupillary distance (IPD) from the head's
centre along the head's own x axis (left at -x, right at +x), looking where the head looks.
Server and client must agree on that, and on which eye each frame of a stereo session is
rendered from (Schollmeyer et al. 2017, Sec. 5 and Fig. 10):

- ``cyclops``: every frame from the head's centre (today's dual view), warped into both eyes;
- ``alternate``: frame k from the left eye when k is even, the right eye when it is odd; the
  client keeps the newest frame of each eye;
- ``per-eye``: both eyes every server tick (two frames per tick, twice the server's work), the
  upper bound the other two are measured against.
"""
from __future__ import annotations

from .errors import ConfigError
from .pose import Pose

#: The default interpupillary distance (mm): the adult median is about 63-64 mm.
DEFAULT_IPD_MM = 64.0
#: Beyond this an IPD is a typo (adults range about 50-75 mm).
MAX_IPD_MM = 100.0
EYES = ("left", "right")
#: Where a stereo session's frames are rendered from (module docstring).
STEREO_REFERENCES = ("cyclops", "alternate", "per-eye")
#: A frame's eye tag: the head's centre (mono and cyclops), or one eye.
CENTRE = "centre"


def check_ipd_mm(ipd_mm: float) -> float:
    """``ipd_mm`` as a float, or a ConfigError naming the problem."""
    try:
        value = float(ipd_mm)
    except (TypeError, ValueError):
        raise ConfigError(f"the interpupillary distance must be a number of millimetres, got {ipd_mm!r}") from None
    if not (0.0 < value <= MAX_IPD_MM):
        raise ConfigError(f"the interpupillary distance must be in (0, {MAX_IPD_MM:g}] mm, got {ipd_mm!r}")
    return value


def eye_offset(eye: str, ipd_mm: float = DEFAULT_IPD_MM) -> Pose:
    """The eye's pose in the head's frame: half the IPD along the head's x axis (left at -x)."""
    if eye == CENTRE:
        return Pose.identity()
    if eye not in EYES:
        raise ConfigError(f"unknown eye {eye!r}; choose from {', '.join(EYES)}")
    half = 0.5e-3 * check_ipd_mm(ipd_mm)
    return Pose.make((-half if eye == "left" else half, 0.0, 0.0))


def eye_pose(head: Pose, eye: str, ipd_mm: float = DEFAULT_IPD_MM) -> Pose:
    """The world pose of ``eye`` (left, right or centre) of a head at ``head``."""
    return head.compose(eye_offset(eye, ipd_mm))


def eye_poses(head: Pose, ipd_mm: float = DEFAULT_IPD_MM) -> tuple[Pose, Pose]:
    """(left, right) world poses of the eyes of a head at ``head``."""
    return eye_pose(head, "left", ipd_mm), eye_pose(head, "right", ipd_mm)


def check_reference(reference: str) -> str:
    if reference not in STEREO_REFERENCES:
        raise ConfigError(f"unknown stereo reference {reference!r}; choose from {', '.join(STEREO_REFERENCES)}")
    return reference


def frame_eyes(reference: str | None, frame_index: int) -> tuple[str, ...]:
    """The eyes the server renders for its ``frame_index``-th server tick, one frame each:
    ``(centre,)`` for mono (``reference`` None) and cyclops, one eye alternating for alternate
    (the left on even ticks), both for per-eye."""
    if reference is None or reference == "cyclops":
        return (CENTRE,)
    check_reference(reference)
    if reference == "alternate":
        return (EYES[frame_index % 2],)
    return EYES
