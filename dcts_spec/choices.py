"""Values the command line offers as choices, in a module that imports nothing heavy.

The code behind them (the C build, the runtimes) imports CasADi, Pinocchio and MuJoCo; keeping
the names here lets `dcts --help` list them and `dcts validate` start without loading those.
The formulations' names are the spec language's (`spec.controller.Formulation`).
"""

RUNTIMES = ("c", "python")  # sim.runtime.make_runtime
TARGETS = ("host", "cortex-m7")  # codegen.build.compile_bundle
