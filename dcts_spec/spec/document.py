"""The whole spec: one YAML file."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BeforeValidator, ConfigDict, Field, PrivateAttr

from .controller import ControllerSpec
from .limits import LimitsSpec
from .parameters import ParametersSpec
from .robot import RobotSpec
from .scenario import ScenarioSpec
from .source import SourceMap
from .tasks import TaskSpec
from .types import IDENTIFIER, StrictModel


def _not_a_boolean(value: Any) -> Any:
    """`version: true` is not version 1 (Python's True == 1 would pass the literal)."""
    if isinstance(value, bool):
        raise ValueError(f"expected the number 1, got {str(value).lower()}")
    return value


# The bundle's <name>.h and <name>.c sit next to the DAQP sources it compiles, whose files
# include each other by these names: a spec named like one shadowed DAQP's header, and the C did
# not compile (`name: api`; first seen from outside). Case-insensitive file systems included.
DAQP_FILE_NAMES = ("api", "auxiliary", "avi", "bnb", "constants", "daqp", "daqp_prox", "eq_elim", "factorization",
                   "hierarchical", "presolve", "types", "utils")
# The C standard's headers: a build that puts the bundle's folder on the include path (CMake's
# target_include_directories) found `name: math`'s math.h instead of the system's (isfinite
# undeclared), and a program including <time.h> next to a `name: time` bundle did not compile.
C_HEADER_NAMES = ("assert", "complex", "ctype", "errno", "fenv", "float", "inttypes", "iso646", "limits", "locale",
                  "math", "setjmp", "signal", "stdalign", "stdarg", "stdatomic", "stdbool", "stddef", "stdint", "stdio",
                  "stdlib", "stdnoreturn", "string", "tgmath", "threads", "time", "uchar", "wchar", "wctype")


def _not_a_shadowing_name(value: Any) -> Any:
    """A spec name that is not the stem of a C file its bundle's own files could be mistaken for."""
    for names, what in ((DAQP_FILE_NAMES, "one of DAQP's C files, which the bundle compiles next to its own"),
                        (C_HEADER_NAMES, f"a C standard header, which the bundle's {value}.h would shadow where its "
                                         "folder is on the include path")):
        if isinstance(value, str) and value.lower() in names:
            raise ValueError(f"{value!r} is the name of {what}; choose another (reserved: {', '.join(names)})")
    return value


class Spec(StrictModel):
    """A robot, its prioritized tasks and limits, the controller settings and a simulation scenario."""

    model_config = ConfigDict(json_schema_extra={"examples": [{
        "version": 1,
        "name": "minimal",
        "robot": {"model": "iiwa14"},
        "limits": {"joint_torque": {"max": 100}},
        "tasks": [
            {"name": "tool_position", "type": "position", "frame": "tool", "priority": 1,
             "gains": {"kp": 100, "kd": 20}, "reference": {"position": [0.5, 0.0, 0.6]}},
            {"name": "damping", "type": "joint", "priority": 2, "gains": {"kp": 0, "kd": 5}},
        ],
        "scenario": {"duration": 2.0, "initial_q": [0, 30, 0, -60, 0, 60, 0], "unit": "deg"},
    }]})

    version: Annotated[Literal[1], BeforeValidator(_not_a_boolean)] = Field(description="spec language version; 1 is the only one", examples=[1])
    name: Annotated[str, AfterValidator(_not_a_shadowing_name)] = Field(
        pattern=IDENTIFIER,
        max_length=64,
        description="identifier (letters, digits, _; at most 64 characters); prefixes the generated C symbols "
        "and names the output folders",
        examples=["minimal", "pick_and_place"],
    )
    robot: RobotSpec = Field(description="the robot to control: a built-in model or a URDF",
                             examples=[{"model": "iiwa14"}, {"urdf": "robots/my_arm.urdf"}])
    limits: LimitsSpec = Field(default_factory=LimitsSpec, description=(
        "joint and Cartesian bounds the controller keeps; joint bounds default to the URDF's"),
        examples=[{"joint_torque": {"max": 100}}])
    controller: ControllerSpec = Field(default_factory=ControllerSpec, description="formulation and its settings",
                                       examples=[{"formulation": "dcts", "period": 0.001}])
    tasks: list[TaskSpec] = Field(min_length=1, description="what the robot should do, by priority (at least one task)",
                                  examples=[[{"name": "damping", "type": "joint", "priority": 1, "gains": {"kp": 0, "kd": 5}}]])
    parameters: ParametersSpec | None = Field(
        None, description="values the compiled controller lets the firmware change at run time (gains, references, "
        "limits narrowing only, task activation), ramped without a bump", examples=[{"tasks": {"tool_position": ["kp", "kd"]}}])
    scenario: ScenarioSpec | None = Field(None, description="what `dcts simulate` runs; not needed to compile",
                                          examples=[{"duration": 2.0}])

    _source: SourceMap = PrivateAttr(default_factory=lambda: SourceMap("<spec>"))

    @property
    def source(self) -> SourceMap:
        """Where each key of the spec was written (file, line, column)."""
        return self._source

    @property
    def base_dir(self) -> Path:
        """Folder relative paths in the spec (e.g. robot.urdf) are resolved against."""
        file = Path(self._source.file)
        return file.parent if file.suffix else Path.cwd()

    @property
    def priority_levels(self) -> list[int]:
        """Distinct priorities, highest (smallest number) first."""
        return sorted({t.priority for t in self.tasks})

    def tasks_at(self, priority: int) -> list[TaskSpec]:
        return [t for t in self.tasks if t.priority == priority]

    def priority_path(self, priority: int) -> tuple[str, int, str]:
        """Where a priority level is written: the `priority` key of its first task."""
        return "tasks", self.tasks.index(self.tasks_at(priority)[0]), "priority"
