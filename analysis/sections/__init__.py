"""The report's sections, one module each: force estimation, characterisation, tracking, slip,
stream health.

Each section is a function of the report run (`analysis.report_run.ReportRun`): it reads the loaded
campaign and what earlier sections left on the run (the T-s5 model, the calibration features),
writes its part of `run.results`, and draws its figures into `run.out`.
"""
