# café
class Show:
    pass
