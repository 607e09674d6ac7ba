"""One folder per FMU: ``config.py`` (its variable table) and ``model.c`` (its equations)."""

#: FMI 2.0 FMU name -> module with ``spec() -> ModelSpec``.
MODELS = {
    "Plant": "pendulab.fmu.models.plant.config",
    "Controller": "pendulab.fmu.models.controller.config",
    "Supervisor": "pendulab.fmu.models.supervisor.config",
    "Seesaw": "pendulab.fmu.models.seesaw.config",
}
#: FMI 3.0 FMU name -> the FMI 2.0 model (a key of MODELS) whose variable table and model.c it is built from.
FMI3_MODELS = {"Plant3": "Plant", "Seesaw3": "Seesaw"}
#: Every FMU that ``build_fmus.py`` makes, in build order.
ALL_FMUS = (*MODELS, *FMI3_MODELS)
