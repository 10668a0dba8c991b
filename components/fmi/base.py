"""The one pythonfmu slave of every robofmu block: a thin FMI wrapper over an FMI-free block.

The generated script of each FMU (``robofmu build``) names the robot and the block kind and
robofmu's version; the slave builds that block (:mod:`robofmu.components.blocks`) for the
robot and maps the FMI calls onto it. :class:`BlockSlave` is composed of one mixin per job,
each in its own module:

- :mod:`.variables`: the block's variables registered with pythonfmu (a value reference is the
  variable's slot in :attr:`Block.values`), fmi2Get* / fmi2Set*;
- :mod:`.outputs`: outputs computed when read, never a non-finite one;
- :mod:`.lifecycle`: fmi2SetupExperiment, initialization (``configure()``), fmi2DoStep
  (``advance(t, h)``), fmi2Terminate;
- :mod:`.fmu_state`: fmi2GetFMUstate / fmi2SetFMUstate and their serialized forms;
- :mod:`.fast_path`: the hot calls served by robofmu's export library itself, and the flags
  shared with it;
- :mod:`.reporting`: failed calls and refused steps as the importer sees them (FMI statuses);
- :mod:`.pythonfmu_workarounds`: pythonfmu 0.7.0's loader, exception handler and strings.

What the slave shares with robofmu's export library is defined in :mod:`.contract`; the model
description pythonfmu writes is completed by :mod:`.model_description`.
"""
from __future__ import annotations

import functools
import importlib.metadata
from pathlib import Path
from xml.etree.ElementTree import Element

from pythonfmu import Fmi2Slave
from pythonfmu.default_experiment import DefaultExperiment

from .. import SOURCE_HASH, STEP_SIZE, check_bundle, description_hash
from ..blocks import block_type
from ..robots import load_description, load_model
from ..robots.description import read
from .fast_path import FastPath
from .fmu_state import FmuState
from .lifecycle import LifeCycle
from .model_description import PYTHON, complete
from .outputs import Outputs
from .pythonfmu_workarounds import balance_pythonfmu_refcount, guard_entry_points
from .reporting import Reporting, behind_robofmu_library
from .variables import Variables

__all__ = ["BlockSlave", "ROBOT_FOLDER", "fmu_version"]

#: The folder of a FMU's ``resources`` that holds its robot's data (``<robot>.toml``, ``<robot>.urdf``).
ROBOT_FOLDER = "robot"


def fmu_version(robofmu_version: str, robot_data: str) -> str:
    """A FMU's model-description ``version``: ``<robofmu version>+<code hash>.<robot data hash>``
    (the first 12 hex digits of :data:`~robofmu.components.SOURCE_HASH`, the first 8 of the
    robot's :func:`~robofmu.components.robot_data_hash`; a PEP 440 local version), so it changes
    with robofmu's version, its code and the FMU's own robot's data, and with nothing else."""
    return f"{robofmu_version}+{SOURCE_HASH[:12]}.{robot_data[:8]}"


@functools.lru_cache(maxsize=None)
def _installed_version() -> str:
    """The installed robofmu distribution's version (its package metadata), or "unknown"."""
    try:
        return importlib.metadata.version("robofmu")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


class BlockSlave(FastPath, LifeCycle, Outputs, FmuState, Variables, Reporting, Fmi2Slave):
    """The FMU of one block of one robot; the generated script sets ``robot_name``,
    ``block_kind`` and ``robofmu_version``."""

    robot_name: str = ""
    block_kind: str = ""
    #: robofmu's version, as ``robofmu build`` writes it into the FMU's script from robofmu's
    #: package metadata (robofmu itself need not be installed where a FMU runs); empty (a slave
    #: made outside a FMU): the installed distribution's.
    robofmu_version: str = ""

    def __init__(self, **kwargs):
        self._share_flags()             # first: the flags live in the struct shared with the library
        super().__init__(**kwargs)
        self._statuses = behind_robofmu_library(self.resources)     # see reporting
        balance_pythonfmu_refcount(type(self))
        if self.resources:
            check_bundle(self.resources)
        if not self.robot_name or not self.block_kind:
            raise TypeError(f"{type(self).__name__}: robot_name and block_kind must be set")
        description = self._own_description()
        self.robot_data = description_hash(description)
        kind, self.profile, description = description.block_of(self.block_kind)   # trajectory_<profile>
        self.logic = block_type(description, kind)(load_model(description))
        self.logic.logger = self._log_from_block
        self.author = "robofmu"
        self.version = fmu_version(self.robofmu_version or _installed_version(), self.robot_data)
        self.description = (f"robofmu {self.block_kind} block of robot '{self.robot_name}': {self.logic.summary}. "
                            f"Runs in Python {PYTHON} with the packages of resources/requirements.txt")
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=self.logic.nominal_stop_time(),
                                                    step_size=STEP_SIZE)
        self.time = 0.0
        self._dirty = True
        self._inputs_checked = False
        self._initialized = False
        self._terminated = False
        self._held_warned = False
        self._bad_output: str | None = None     # why the outputs are held (the next step fails)
        self._register_variables()
        self._feedthrough = self.logic.feedthrough   # outputs that depend on inputs (else on state only)
        self._prepare_fast_path()
        if self._statuses:
            self.fast_path = self._register_fast_path()       # last: the instance is complete

    def _own_description(self):
        """The robot's description from this FMU's own resources folder: ``resources/robot/``
        holds the robot's TOML as ``<robot>.toml`` and, for a URDF robot, the URDF it resolved
        to at build as ``<robot>.urdf`` (wherever it was: beside the TOML, or in an installed
        distribution), so the FMU needs neither the robot's folder nor that distribution.

        All pythonfmu FMUs of a process share one interpreter, so the robofmu package is the one
        imported first, perhaps from another FMU's extraction folder that its importer has since
        deleted; the bundled package holds no robot's data anyway. Robot data is therefore read
        from this instance's own folder, which lives as long as the instance. A slave made
        outside a FMU (no resources) reads the package's robot of its name."""
        if not self.resources:
            return load_description(self.robot_name)
        folder = Path(self.resources) / ROBOT_FOLDER
        urdf = folder / f"{self.robot_name}.urdf"
        return read(folder / f"{self.robot_name}.toml", urdf=urdf if urdf.is_file() else None)

    def to_xml(self, model_options=dict()) -> Element:
        """pythonfmu's model description, completed (see :mod:`.model_description`)."""
        return complete(super().to_xml(model_options), self.logic, self.robot_name, self.logic.kind, self.profile,
                        self.robot_data)


guard_entry_points(BlockSlave)
