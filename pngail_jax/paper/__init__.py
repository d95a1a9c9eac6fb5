"""The paper's experiments: ``plan`` (its figures, tables and budgets as data, and the grids
behind them), ``grids`` (making demonstrations and running each grid through the runner) and
``page`` (the results page). ``python -m experiments.paper`` is their command line."""
