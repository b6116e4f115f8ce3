"""The one error type users see: a one-line message naming the file, the feature and the fault."""


class InputError(Exception):
    """Bad input. ``str(err)`` is a complete one-line message for the operator."""

    def __init__(self, path, message, feature=None):
        self.path = str(path) if path is not None else None
        # one line, whatever a library or a hostile file put in the text
        self.feature = None if feature is None else " ".join(str(feature).split())
        message = " ".join(str(message).split())
        if len(message) > 300:
            message = message[:297] + "..."
        self.message = message
        where = self.path or "<input>"
        if self.feature is not None:
            where = f"{where}: {self.feature[:120]}"
        super().__init__(f"{where}: {message}")
