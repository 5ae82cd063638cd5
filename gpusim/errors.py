"""User-facing errors.

Every mistake a user can make (bad file, bad key, bad value) raises a
:class:`GpusimError` whose message is one line naming the problem and the fix.
The CLI prints it without a traceback and exits non-zero.
"""


class GpusimError(Exception):
    """A problem with the user's input, reported as one line."""


class ConfigError(GpusimError):
    """A configuration file or override names an unknown key or an invalid value.

    ``key`` is the dotted key at fault when there is one, and ``problem`` the
    message without the file and key (so a caller can blame the override that
    set the key instead of the file).
    """

    def __init__(self, message: str, key: str | None = None, problem: str | None = None):
        super().__init__(message)
        self.key = key
        self.problem = problem or message


class TraceError(GpusimError):
    """A fragment trace is malformed, truncated or out of range.

    ``fragment`` is the index of the offending fragment when there is one, and
    ``problem`` the message without the file name (so importers can name a line).
    """

    def __init__(self, message: str, fragment: int | None = None, problem: str | None = None):
        super().__init__(message)
        self.fragment = fragment
        self.problem = problem or message
