"""Exceptions with messages a user can act on; the CLI and the app print them as one line."""


class AutoTrackError(Exception):
    """Base class for every error this package raises on purpose."""


class InputError(AutoTrackError):
    """A sequence, image, video or file cannot be read or is malformed."""


class BoxError(InputError):
    """A bounding box is malformed, empty or outside the image."""


class SceneError(AutoTrackError):
    """A localisation scene description is invalid."""


class SessionError(AutoTrackError):
    """A session recording cannot be written or read."""


class MissingExtraError(AutoTrackError):
    """An optional part of the package is not installed (`autotrack.extras`)."""
