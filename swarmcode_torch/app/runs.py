"""Run directories, by the names the rest of the package and its users import from here. Each
job has its own module:

- `files`: the run directory's files, atomic writes and appends, reads that never follow a link;
- `locks`: one live process per run (or sweep) directory (`RunLock`);
- `migrations`: a config written by any version read as this version's (`migrate_config`), and
  the retired settings a resume refuses (`check_runnable`);
- `runconfig`: config.toml, the run's own scenario.toml and hardware.toml, and the checks a
  config passes before a run starts (settings, memory);
- `checkpoints`: checkpoint.pt written, loaded with the run and resumed, branched from;
- `checkpoint_read`: a checkpoint file read back without running code, its records checked;
- `summary`: summary.json and teams.jsonl, written every generation and read back checked;
- `signals`: the steps Ctrl-C and SIGTERM must not split;
- `session`: how a run starts, runs (the generation loop, `run`) and ends.

docs/RELIABILITY.md lists what the files promise and the tests that show it.
"""

from __future__ import annotations

from .checkpoint_read import read_checkpoint
from .checkpoints import (
    CheckpointReporter,
    check_copies,
    copy_digests,
    load_checkpoint,
    load_run,
    resume,
    save_checkpoint,
)
from .files import (
    ATOMIC_FILES,
    BUDGET_PLOT,
    CHECKPOINT_FILE,
    CONFIG_FILE,
    HARDWARE_COPY,
    LOCK_FILE,
    MAX_RECORD_BYTES,
    MAX_TEXT_BYTES,
    METRICS_FILE,
    PARTIAL_SUFFIX,
    REPLAY_FILE,
    RUN_FILES,
    SCENARIO_COPY,
    SUMMARY_FILE,
    SWEEP_LOCK_FILE,
    TABLE_CSV,
    TABLE_MD,
    TEAMS_FILE,
    RunError,
    append_line,
    atomic_write_bytes,
    check_nesting,
    clean_temporary_files,
    current_umask,
    interrupt_point,
    new_run_dir,
    open_nofollow,
    os_error_text,
    prepare_run_dir,
    read_file_bytes,
    read_text,
    refuse_links,
    repair_teams,
    run_dir_name,
    trim_teams,
)
from .locks import RunLock
from .migrations import (
    LEGACY_DEFAULTS,
    LEGACY_EPISODE_TICKS,
    RETIRED_SETTINGS,
    RETIRED_VALUES,
    check_runnable,
    drop_retired_settings,
    migrate_config,
    retired_setting,
    retired_value,
)
from .runconfig import (
    CONFIG_REQUIRED,
    FALLBACK_MEMORY,
    check_config,
    check_memory,
    config_differences,
    config_from_dict,
    config_to_toml,
    estimate_bytes,
    hardware_bytes,
    memory_limit,
    read_config,
    run_catalog,
    run_scenario,
    run_scenario_source,
    write_config,
    write_run_files,
)
from .session import Reporter, run
from .signals import deferred_signals, interrupt_of
from .summary import (
    MAX_TEAM,
    SummaryReporter,
    check_designs,
    generation_team,
    read_summary,
    read_teams,
)

__all__ = [
    "CheckpointReporter",
    "check_copies",
    "copy_digests",
    "load_checkpoint",
    "load_run",
    "read_checkpoint",
    "resume",
    "save_checkpoint",
    "ATOMIC_FILES",
    "BUDGET_PLOT",
    "CHECKPOINT_FILE",
    "CONFIG_FILE",
    "HARDWARE_COPY",
    "LOCK_FILE",
    "MAX_RECORD_BYTES",
    "MAX_TEXT_BYTES",
    "METRICS_FILE",
    "PARTIAL_SUFFIX",
    "REPLAY_FILE",
    "RUN_FILES",
    "SCENARIO_COPY",
    "SUMMARY_FILE",
    "SWEEP_LOCK_FILE",
    "TABLE_CSV",
    "TABLE_MD",
    "TEAMS_FILE",
    "RunError",
    "append_line",
    "atomic_write_bytes",
    "check_nesting",
    "clean_temporary_files",
    "current_umask",
    "interrupt_point",
    "new_run_dir",
    "open_nofollow",
    "os_error_text",
    "prepare_run_dir",
    "read_file_bytes",
    "read_text",
    "refuse_links",
    "repair_teams",
    "run_dir_name",
    "trim_teams",
    "RunLock",
    "LEGACY_DEFAULTS",
    "LEGACY_EPISODE_TICKS",
    "migrate_config",
    "RETIRED_SETTINGS",
    "RETIRED_VALUES",
    "check_runnable",
    "drop_retired_settings",
    "retired_setting",
    "retired_value",
    "CONFIG_REQUIRED",
    "FALLBACK_MEMORY",
    "check_config",
    "check_memory",
    "config_differences",
    "config_from_dict",
    "config_to_toml",
    "estimate_bytes",
    "hardware_bytes",
    "memory_limit",
    "read_config",
    "run_catalog",
    "run_scenario",
    "run_scenario_source",
    "write_config",
    "write_run_files",
    "Reporter",
    "run",
    "deferred_signals",
    "interrupt_of",
    "MAX_TEAM",
    "SummaryReporter",
    "check_designs",
    "generation_team",
    "read_summary",
    "read_teams",
]
