"""Names vulture (dead-code scan, confidence >= 60) reports that are used where it cannot see.

Each line is a deliberate hook; the comment says who uses it. ``tests/test_dead_code.py`` runs
the scan over components/, system/, tests/, benchmarks/ and this file, and fails on any other
finding. (Not a module anyone imports; ruff skips it.)
"""
# Blocks register by (kind, variant) in Block.__init_subclass__; made by kind, never by class name.
ControllerBlock, FKBlock, IKBlock, JacobianBlock, PlantBlock
WaypointsBlock, LineBlock, JointBangBangBlock, CircleBlock, PoseLineBlock, PoseWaypointsBlock
abstract                # Block.__init_subclass__: a class setting it registers nothing

# IK solvers register by name in their family's registry (the robot description names one).
PitchElbowIK, SphericalIK, PlanarElbowIK, OffsetRRPIK, Planar3RRPIK, NewtonRaphsonIK, DampedLeastSquaresIK

# pythonfmu's Fmi2Slave reads these (model description) and calls these (FMU state hooks).
author, default_experiment
_set_fmu_state, _fmu_state_from_bytes

# fmpy's fmi2CallbackFunctions fields, filled for the FMU to call.
allocateMemory, freeMemory, componentEnvironment

# libcosim's local slave object, kept referenced for as long as the execution runs.
local_slave

# workspace study result: the orientation reaching farthest per ray, for users of the API.
theta_reach

# Dask calls the preload module's dask_setup(worker) when a worker starts.
dask_setup, worker

# pytest finds these by name.
pytest_collection_modifyitems, pytestmark

# expat calls these handlers of the checked URDF reader's parser (a DTD or entity refused unexpanded).
StartDoctypeDeclHandler, EntityDeclHandler
