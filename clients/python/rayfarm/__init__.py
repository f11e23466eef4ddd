"""rayfarm: the Python client of the rayfarm render farm (README.md).

    import rayfarm
    farm = rayfarm.Farm("farm:7070", token_file="~/.rayfarm-token")
    job = farm.submit("shot/scene.json", frames="1-24", spp=256, aovs=["albedo", "normal"])
    for status in job.watch():
        print(f"{status.progress:.0%}")
    for frame in job.fetch("out/shot.####.exr"):
        rayfarm.denoise(frame, frame.exr.replace(".exr", ".denoised.exr"))
"""

from .client import (ENDED, SETTINGS, TLS, Farm, Frame, FrameStatus, Job, JobStatus, TaskAttempt,
                     WorkerStatus, frame_range)
from .errors import (Aborted, AlreadyExists, CommandError, DataLoss, DeadlineExceeded,
                     FailedPrecondition, Internal, InvalidArgument, JobFailed, NotFound,
                     PermissionDenied, RayfarmError, ResourceExhausted, SceneError,
                     Unauthenticated, Unavailable)
from .images import Image, denoise, read_exr, write_exr

__version__ = "0.1.0"

__all__ = [
    "Farm", "Job", "JobStatus", "FrameStatus", "WorkerStatus", "TaskAttempt", "Frame", "TLS",
    "Image", "ENDED", "SETTINGS", "frame_range", "read_exr", "write_exr", "denoise",
    "RayfarmError", "Unavailable", "DeadlineExceeded", "Unauthenticated", "PermissionDenied",
    "NotFound", "InvalidArgument", "FailedPrecondition", "ResourceExhausted", "DataLoss",
    "AlreadyExists", "Aborted", "Internal", "SceneError", "CommandError", "JobFailed",
]
