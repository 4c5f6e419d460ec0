"""Which user the learner's code runs as in graded mode (graders.grading.isolation).

Namespace level: `nobody`, in a file system view that holds nothing of the grader's or of other learners.
Process level as root (a container without CAP_SYS_ADMIN cannot `unshare`): no such view, but the learner
still leaves root, for a uid of its own per grader process (`LEARNER_UID_BASE` + the grader's pid), so that
learners graded at the same time by one batch cannot read each other's homes either. That needs the
interpreter, its standard library and packages readable by anyone (`others_can_read`: not so for a Python
under /root) and a way into the learner's private folder (`open_the_way`).
"""
from __future__ import annotations

import os

LEARNER_UID_BASE = 0x7F000000     # + pid (< 2**22): high uids no distribution gives its users


def nobody() -> tuple[int, int]:
    import grp
    import pwd
    try:
        uid = pwd.getpwnam("nobody").pw_uid
    except KeyError:
        uid = 65534
    for group in ("nogroup", "nobody"):
        try:
            return uid, grp.getgrnam(group).gr_gid
        except KeyError:
            pass
    return uid, 65534


def learner_ids() -> tuple[int, int]:
    """The uid and gid of this grader's learners at process level: their own, not `nobody`."""
    n = LEARNER_UID_BASE + os.getpid() % (1 << 22)
    return n, n


def others_can_read(paths: list[str]) -> bool:
    """Whether a user who owns none of `paths` can reach and read each (every folder on the way o+x, the
    path itself o+r)."""
    for path in map(os.path.realpath, paths):
        try:
            if not os.stat(path).st_mode & 0o004:
                return False
            while path != os.path.dirname(path):
                path = os.path.dirname(path)
                if not os.stat(path).st_mode & 0o001:
                    return False
        except OSError:
            return False
    return True


def open_the_way(folder: str) -> bool:
    """Let other users pass through (not list) the folders above `folder` that this user owns and keeps
    closed (a grade's 0700 temporary folder becomes 0701); False if one it does not own bars the way."""
    path = os.path.realpath(folder)
    while path != os.path.dirname(path):
        path = os.path.dirname(path)
        st = os.stat(path)
        if st.st_mode & 0o001:
            continue
        if st.st_uid != os.geteuid():
            return False
        os.chmod(path, (st.st_mode & 0o7777) | 0o001)
    return True
