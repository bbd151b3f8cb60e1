"""The whole spec: one YAML file."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, PrivateAttr

from .controller import ControllerSpec
from .limits import LimitsSpec
from .robot import RobotSpec
from .scenario import ScenarioSpec
from .source import SourceMap
from .tasks import TaskSpec
from .types import StrictModel


class Spec(StrictModel):
    """A robot, its prioritized tasks and limits, the controller settings and a simulation scenario."""

    version: Literal[1] = Field(description="spec language version")
    name: str = Field(
        pattern=r"^[A-Za-z_][A-Za-z0-9_]*$",
        max_length=64,
        description="identifier; prefixes the generated C symbols",
    )
    robot: RobotSpec
    limits: LimitsSpec = Field(default_factory=LimitsSpec)
    controller: ControllerSpec = Field(default_factory=ControllerSpec)
    tasks: list[TaskSpec] = Field(min_length=1)
    scenario: ScenarioSpec | None = None

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
