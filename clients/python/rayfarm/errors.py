"""Typed exceptions. Every failure of a coordinator call is a RayfarmError subclass chosen by its
gRPC status code (the codes are those of proto/rayfarm.proto's header); failures of the rayfarm
binary the client runs (bundle, fetch) are SceneError or CommandError."""

from __future__ import annotations

import grpc


class RayfarmError(Exception):
    """Base of every error the client raises. `code` is the gRPC status code, when there is one."""

    code: grpc.StatusCode | None = None

    def __init__(self, message: str, code: grpc.StatusCode | None = None):
        super().__init__(message)
        if code is not None:
            self.code = code


class Unavailable(RayfarmError):
    """The coordinator could not be reached (down, or TLS on one side only) within the timeout."""

    code = grpc.StatusCode.UNAVAILABLE


class DeadlineExceeded(RayfarmError):
    code = grpc.StatusCode.DEADLINE_EXCEEDED


class Unauthenticated(RayfarmError):
    """No accepted token: none given, unknown, expired or revoked."""

    code = grpc.StatusCode.UNAUTHENTICATED


class PermissionDenied(RayfarmError):
    """A token of the wrong role, or another tenant's job."""

    code = grpc.StatusCode.PERMISSION_DENIED


class NotFound(RayfarmError):
    """An unknown (or deleted, or expired) job."""

    code = grpc.StatusCode.NOT_FOUND


class InvalidArgument(RayfarmError):
    """A malformed request: a bad frame range, setting or scene."""

    code = grpc.StatusCode.INVALID_ARGUMENT


class FailedPrecondition(RayfarmError):
    """An operation the job's state does not allow (retrying a running job, deleting one without
    force)."""

    code = grpc.StatusCode.FAILED_PRECONDITION


class ResourceExhausted(RayfarmError):
    """Over one of the coordinator's limits (jobs, frames, bytes) or its disk is full."""

    code = grpc.StatusCode.RESOURCE_EXHAUSTED


class DataLoss(RayfarmError):
    """A payload's checksum did not match."""

    code = grpc.StatusCode.DATA_LOSS


class AlreadyExists(RayfarmError):
    code = grpc.StatusCode.ALREADY_EXISTS


class Aborted(RayfarmError):
    code = grpc.StatusCode.ABORTED


class Internal(RayfarmError):
    code = grpc.StatusCode.INTERNAL


class SceneError(InvalidArgument):
    """The scene could not be bundled: a missing file, or one the importers refuse (the message is
    the binary's, naming the file and line). Raised before anything is sent."""

    code = None


class CommandError(RayfarmError):
    """The rayfarm binary failed (fetch); the message is what it printed."""


class JobFailed(RayfarmError):
    """Job.wait() on a job that ended failed or cancelled. `status` is its last JobStatus."""

    def __init__(self, message: str, status):
        super().__init__(message)
        self.status = status


_BY_CODE = {cls.code: cls for cls in (
    Unavailable, DeadlineExceeded, Unauthenticated, PermissionDenied, NotFound, InvalidArgument,
    FailedPrecondition, ResourceExhausted, DataLoss, AlreadyExists, Aborted, Internal)}


def from_rpc_error(error: grpc.RpcError, what: str) -> RayfarmError:
    """The exception for a failed call: its class by status code, its message the coordinator's."""
    code = error.code() if hasattr(error, "code") else None
    details = error.details() if hasattr(error, "details") else str(error)
    cls = _BY_CODE.get(code, RayfarmError)
    name = code.name if code is not None else "UNKNOWN"
    return cls(f"{what}: {name}: {details}", code)
