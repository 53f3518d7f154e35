"""robogs.format: the robogs dataset format — IO, conventions, kinematics, rendering and validation."""

from .dataset import Dataset, Episode
from .errors import (
    DatasetExistsError,
    FormatError,
    InputError,
    LockError,
    PathEscapeError,
    RobogsError,
    VersionError,
)
from .spec_version import SPEC_VERSION
from .writer import DatasetWriter

__all__ = [
    "Dataset",
    "DatasetWriter",
    "Episode",
    "SPEC_VERSION",
    "RobogsError",
    "FormatError",
    "VersionError",
    "PathEscapeError",
    "DatasetExistsError",
    "LockError",
    "InputError",
]
