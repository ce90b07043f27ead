"""Standard components that misbehave on purpose (see types.yaml)."""

import os
import threading
import time


def _log(path, line):
    if path:
        with open(path, "a", encoding="utf-8") as f:
            f.write(line + "\n")


def _forever():
    while True:
        time.sleep(0.05)


class Misbehave:
    def __init__(self, at=0, what="kill", signum=11, seconds=60.0, log="", fail_free=False):
        self.at, self.what, self.signum, self.seconds, self.log = at, what, signum, seconds, log
        self.fail_free = fail_free
        self.frame = 0

    def initialize(self, image):
        _log(self.log, "init misbehave")
        return image

    def execute(self, image):
        if self.frame == self.at:
            if self.what == "kill":
                os.kill(os.getpid(), self.signum)
                time.sleep(5)  # a signal that does not kill: the test sees the run go on
            elif self.what == "sleep":
                time.sleep(self.seconds)
            elif self.what == "loop":
                while True:
                    pass
            elif self.what == "thread":  # a thread that never ends, not a daemon
                threading.Thread(target=_forever, name="busy-worker", daemon=False).start()
            elif self.what == "raise":
                raise RuntimeError(f"injected failure at frame {self.frame}")
        self.frame += 1
        return image

    def free_memory(self):
        _log(self.log, "free misbehave")
        if self.fail_free:
            raise OSError("injected failure to free")


class Tally:
    def __init__(self, log=""):
        self.log = log
        self.frames = 0

    def initialize(self, image):
        self.size = image
        _log(self.log, "init tally")

    def execute(self, image):
        self.frames += 1

    def free_memory(self):
        _log(self.log, "free tally")
