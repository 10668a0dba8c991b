"""pythonfmu wrappers: one slave class per block, thin over the FMI-free logic.

- :mod:`.base`: :class:`~.base.BlockSlave`, the slave every FMU's script derives from, composed of
- :mod:`.variables`: variable registration with pythonfmu and value access (fmi2Get*/fmi2Set*);
- :mod:`.outputs`: outputs computed when read, never a non-finite one;
- :mod:`.lifecycle`: set-up, initialization, steps, termination;
- :mod:`.fmu_state`: FMU states saved, restored and serialized;
- :mod:`.fast_path`: the hot calls served by robofmu's export library, the flags shared with it;
- :mod:`.reporting`: failures and warnings as the importer sees them (FMI statuses);
- :mod:`.pythonfmu_workarounds`: pythonfmu 0.7.0's loader, exception handler and strings;
- :mod:`.contract`: what the slave and robofmu's C libraries share (one definition; the build
  renders it as the C header);
- :mod:`.model_description`: pythonfmu's model description completed;
- :mod:`.quiet`: NumPy's floating-point warnings off, cheaply;
- :mod:`.bundle`: the whole bundled package imported at once.
"""
