"""Errors raised by the kernel runtime."""


class BackendUnavailableError(RuntimeError):
    """A backend was asked for by name (argument or COUPLEKIT_BACKEND) but cannot run here; says why."""


class KernelBuildError(RuntimeError):
    """A kernel failed to compile; the message holds the command and the compiler's output."""


class KernelCacheError(KernelBuildError):
    """The kernel cache folder (``$COUPLEKIT_CACHE_DIR``, else ``$XDG_CACHE_HOME/couplekit/kernels``) cannot be
    made or written: a setting to fix, not a compiler failure."""


class KernelArgumentError(TypeError):
    """A kernel was called with arguments that do not match its C signature."""
