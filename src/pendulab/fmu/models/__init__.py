"""One folder per FMU: ``config.py`` (its variable table) and ``model.c`` (its equations)."""

#: FMU name -> module with ``spec() -> ModelSpec``.
MODELS = {
    "Plant": "pendulab.fmu.models.plant.config",
    "Controller": "pendulab.fmu.models.controller.config",
    "Supervisor": "pendulab.fmu.models.supervisor.config",
}
