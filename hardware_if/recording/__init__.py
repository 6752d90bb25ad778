"""A run's recording: written to MCAP as it happens, then read back, summarised and plotted (``replay``).

:mod:`~hardware_if.recording.recorder` writes the file through :mod:`~hardware_if.recording.checked_file`
(every write checked; a failure is a hold); :mod:`~hardware_if.recording.reader` reads an MCAP file record by
record within stated limits and :mod:`~hardware_if.recording.schema` checks each message of the JSON
channels as it is read; :mod:`~hardware_if.recording.replay` summarises a recording and
:mod:`~hardware_if.recording.replay_figure` plots it.

Imports: :mod:`hardware_if.common` only. A recording is read without a console, a client or ROS.

``hardware_if.recording`` was the recorder's module before the rooms: its names are kept here for user
scripts. The project imports them from :mod:`hardware_if.recording.recorder`.
"""

from hardware_if.recording.recorder import (
    CHANNELS,
    CHUNK_SIZE_BYTES,
    FLUSH_PERIOD_S,
    Recorder,
    RecordingRead,
    read_recording,
)

__all__ = ["CHANNELS", "CHUNK_SIZE_BYTES", "FLUSH_PERIOD_S", "Recorder", "RecordingRead", "read_recording"]
