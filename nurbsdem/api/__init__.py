"""The parts of :class:`nurbsdem.simulation.Simulation`, the Python API: the checks of its
arguments against the deck's rules (:mod:`.checks`), the scene's entries (:mod:`.scene`), the
steps' arguments (:mod:`.steps`), the solver made and started at the first step
(:mod:`.start`), the state read between steps (:mod:`.state`) and the restart from a
checkpoint of a scene built in Python (:mod:`.restart`)."""
