"""Identification: calibrate the model to measured data (``fit``) and name what it gets wrong (``diagnose``).

One idea per module: ``record`` (the data and its checks), ``simulation`` (free runs on a record),
``metrics`` (NRMSE fit, noise floor), ``parameters`` (free-parameter handles), ``output_error``
(the bounded least-squares fit), ``calibration`` and ``fitting`` (nominal parameters),
``residual_tests`` and ``signatures`` (evidence), ``candidates`` (the effect bank as extensions),
``selection`` (the decision rule), ``diagnosis`` (the procedure) and ``report`` (the outputs; the
parameter file itself is ``sim_core.params_file``).
"""
