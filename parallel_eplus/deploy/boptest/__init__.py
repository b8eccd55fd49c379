"""`parallel-eplus boptest`: BOPTEST's service API (ibpsa/project1-boptest, `service/web/server/docs/openapi.yaml`)
over every building this package runs, each test one EnergyPlus episode (docs/boptest.md).

- `points.py`: a building's inputs (`<name>_u`, `<name>_activate`), measurements (`<name>_y`) and forecast points,
  in BOPTEST's SI units;
- `scenario.py`: BOPTEST's scenarios (time period, electricity price, forecast uncertainty, seed);
- `forecast.py`: the weather file's and the tariffs' coming values, with BOPTEST's forecast errors;
- `kpi.py`: BOPTEST's core KPIs from the episode's step table (buildings/scoring/kpis.py);
- `test.py`: one test: an EnergyPlus episode stepped per `advance`;
- `registry.py`: the test cases and the tests (worker limit, queue, idle timeout, stop; on Ray: `remote.py`);
- `app.py`: the FastAPI routes and BOPTEST's `{message, payload, status}` envelope.

Beside bacnet and export: imports serve (its token and request log), evaluation, envs, engine and buildings.
"""
