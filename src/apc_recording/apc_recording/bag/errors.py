"""The errors of the bag package: one for a bag that cannot be used, one for a truncated bag."""

from __future__ import annotations


class BagError(Exception):
    """A bag cannot be written or read as asked; the message says what and where."""


class BagTruncatedWarning(UserWarning):
    """A bag ends without its footer (the writer was killed); only complete chunks were read."""
