

class Displayer:
    pass


class Window:
    def Display(self):
        pass
