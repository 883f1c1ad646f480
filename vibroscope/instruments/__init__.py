"""The founding paper's virtual instruments, rebuilt as scriptable models.

Olaru & Olaru (2011) describe LabVIEW instruments for a linear pneumatic motor and the
influence of its constructive parameters, a linear hydraulic motor under P and PD2 position
control, a block schema with a PI regulator and a first-order correction (indicial response
at every point), a magnetorheological damper, and comparative sweeps.  One module each:

- :mod:`vibroscope.instruments.lti`: Bode, Nyquist and step responses with their criteria
  (python-control), :class:`BodeResult`, :class:`NyquistResult`, :class:`StepResult`;
- :mod:`vibroscope.instruments.block_schema`: :class:`BlockSchema` (signal graphs of LTI
  blocks) and the paper's PI + correction schema :func:`paper_block_schema`;
- :mod:`vibroscope.instruments.pneumatic`: :func:`pneumatic_motor` (paper eq. 1-3);
- :mod:`vibroscope.instruments.hydraulic`: :func:`hydraulic_motor`, P vs PD2
  :func:`hydraulic_comparison` (Merritt 1967);
- :mod:`vibroscope.instruments.mr_damper`: Spencer et al. (1997) MR damper with cubic
  current laws (paper eq. 5), :func:`simulate_mr_damper`;
- :mod:`vibroscope.instruments.influence`: influence coefficients (paper eq. 2-3, Table 1);
- :mod:`vibroscope.instruments.sweeps`: comparative sweeps (``vibroscope compare``);
- :mod:`vibroscope.instruments.scenarios`: the paper's figures computed (what the viewer draws).

The instruments use :mod:`vibroscope.models` (the MR-damper law of its elements, model
files); their figures live in :mod:`vibroscope.viewers.instruments`.

References
----------
.. [1] A. Olaru and S. Olaru, "Assisted dynamic behavior optimization with LabVIEW
   instrumentation", Proc. CSIT vol. 1, IACSIT Press, Singapore, 2011.
"""
