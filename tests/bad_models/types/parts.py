"""Classes of the standard test types (never imported by check)."""


class Source:
    def __init__(self, **params):
        self.params = params


class Sink:
    def __init__(self, **params):
        self.params = params
