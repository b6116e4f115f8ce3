"""The one error type users see: a one-line message naming the file, the feature and the fault."""


class InputError(Exception):
    """Bad input. ``str(err)`` is a complete one-line message for the operator."""

    def __init__(self, path, message, feature=None):
        self.path = str(path) if path is not None else None
        self.feature = feature
        self.message = message
        where = self.path or "<input>"
        if feature is not None:
            where = f"{where}: {feature}"
        super().__init__(f"{where}: {message}")
