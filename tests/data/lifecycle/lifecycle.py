"""Components for lifecycle tests: one raises at a chosen frame, one fails to free or
to construct."""


def _log(path, line):
    if path:
        with open(path, "a", encoding="utf-8") as f:
            f.write(line + "\n")


class Flaky:
    def __init__(self, fail_at=-1, log="", fail_initialize=False):
        self.fail_at, self.log, self.fail_initialize = fail_at, log, fail_initialize
        self.frame = 0

    def initialize(self, image):
        if self.fail_initialize:
            raise RuntimeError("injected failure to initialize")
        return image

    def execute(self, image):
        if self.frame == self.fail_at:
            raise RuntimeError(f"injected failure at frame {self.frame}")
        self.frame += 1
        return image

    def free_memory(self):
        _log(self.log, "free flaky")


class Recorder:
    def __init__(self, fail_free=False, log="", fail_init=False):
        if fail_init:
            raise ValueError("injected failure to construct")
        self.fail_free, self.log = fail_free, log
        self.frames = 0

    def initialize(self, mask):
        self.size = mask

    def execute(self, mask):
        self.frames += 1

    def free_memory(self):
        _log(self.log, "free recorder")
        if self.fail_free:
            raise OSError("injected failure to free")
