class Level:
    def __init__(self, level):
        self.level = level
