"""The paper's experiments: ``plan`` (its figures, tables and budgets as data, and the grids
behind them), ``grids`` (making demonstrations and running each grid through the sweep job) and
``page`` (the results page), and ``run`` (the plan as one job: ``run_paper``).
``python -m experiments.paper`` is its command line."""
