def table(src, *, lut, k, poly, bad_default=None, bad_dim=None, bad_element=None, huge=None,
          ragged=None):
    return src
