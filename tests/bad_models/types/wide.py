class Widen:
    pass
