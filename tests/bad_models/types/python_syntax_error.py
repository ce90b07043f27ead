class Show:
    def __init__(self)
        pass
