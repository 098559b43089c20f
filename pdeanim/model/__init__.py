"""The dynamic-PDE curve model: closed-form families of m w_tt = D w_uuuu, fitting, clip format, baselines."""
