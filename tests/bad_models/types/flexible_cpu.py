"""CPU functions for tests/bad_models/types/flexible.yaml: never imported by check."""

raise RuntimeError("check imported user code")


def copy(image):
    return image.copy()


def needs_more(image, scale):
    return image * scale
