"""Exceptions that the command line turns into exit codes."""


class InputError(ValueError):
    """Bad input: a file, dataset, attribute or option that breaks a rule.

    The message names the file, the dataset (or option), the sample index where
    it applies and what is wrong.  The command line prints it on one line and
    exits with code 2.
    """

    def __init__(self, message, *, path=None, dataset=None, index=None):
        parts = []
        if path is not None:
            parts.append(str(path))
        if dataset is not None:
            parts.append(str(dataset))
        where = ": ".join(parts)
        if index is not None:
            where = f"{where} [sample {index}]" if where else f"[sample {index}]"
        super().__init__(f"{where}: {message}" if where else message)
        self.reason = message
        self.path = path
        self.dataset = dataset
        self.index = index
