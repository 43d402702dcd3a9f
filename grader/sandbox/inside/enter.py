"""First process of a sandbox (stdlib only; run by grader.sandbox.namespaces inside fresh namespaces).

As (namespace) root: build a private root from read-only binds and tmpfs, bring up the
loopback interface, enter the root, drop to the sandbox user with rlimits and no way to
regain privileges, then exec the command. Any failure exits with status 125.
"""

import ctypes
import ctypes.util
import json
import os
import resource
import socket
import subprocess
import sys

MS_RDONLY, MS_NOSUID, MS_NODEV, MS_NOEXEC = 1, 2, 4, 8
MS_REMOUNT, MS_BIND, MS_REC, MS_PRIVATE = 32, 4096, 16384, 1 << 18
PR_SET_NO_NEW_PRIVS = 38

libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
libc.mount.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p, ctypes.c_ulong, ctypes.c_char_p]


def mount(source, target, fstype, flags, data=None):
    enc = (lambda s: None if s is None else s.encode())
    if libc.mount(enc(source), enc(target), enc(fstype), flags, enc(data)) != 0:
        e = ctypes.get_errno()
        raise OSError(e, f"mount {source} -> {target}: {os.strerror(e)}")


def inside(root, path):
    return os.path.join(root, path.lstrip("/"))


def bind(root, src, readonly=True, extra=0):
    dst = inside(root, src)
    if os.path.islink(src) and os.path.dirname(src) == "/":  # /bin -> usr/bin on merged-/usr systems
        if not os.path.lexists(dst):
            os.symlink(os.readlink(src), dst)
        return
    if os.path.isdir(src):
        os.makedirs(dst, exist_ok=True)
    else:
        os.makedirs(os.path.dirname(dst), exist_ok=True)
        if not os.path.exists(dst):
            open(dst, "w").close()
    mount(src, dst, None, MS_BIND | MS_REC)
    if readonly:
        mount(None, dst, None, MS_REMOUNT | MS_BIND | MS_RDONLY | MS_NOSUID | MS_NODEV | extra)


def enter(cfg):
    """Build the sandbox from ``cfg`` and enter it: its root, folder, limits and user."""
    root = cfg["root"]
    lim = cfg["limits"]
    if cfg.get("gate"):  # the grader's gate (outside the new root, root's only): kept open as an fd
        gate = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        gate.connect(cfg["gate"])
        fd = gate.detach()
        os.set_inheritable(fd, True)
        cfg["env"] = {**cfg["env"], "SNAKEKIT_GATE_FD": str(fd)}
    mount(None, "/", None, MS_REC | MS_PRIVATE)
    mount("tmpfs", root, "tmpfs", MS_NOSUID | MS_NODEV, "mode=0755,size=4m")
    for d in ("tmp", "proc", "dev", "dev/shm"):
        os.makedirs(inside(root, d), exist_ok=True)
    # the private /tmp first: a kit installed under /tmp (a fresh clone there) is bound into it
    mount("tmpfs", inside(root, "tmp"), "tmpfs", MS_NOSUID | MS_NODEV, f"mode=1777,size={lim['tmp']}")
    for src in cfg["binds"]:
        bind(root, src)
    for path in cfg["hide"]:
        if os.path.isdir(inside(root, path)):
            mount("tmpfs", inside(root, path), "tmpfs", MS_RDONLY | MS_NOSUID | MS_NODEV | MS_NOEXEC, "size=4k,mode=0555")
    mount("proc", inside(root, "proc"), "proc", MS_NOSUID | MS_NODEV | MS_NOEXEC)
    mount("tmpfs", inside(root, "dev"), "tmpfs", MS_NOSUID | MS_NOEXEC, "mode=0755,size=64k")
    for node in ("null", "zero", "full", "random", "urandom"):
        bind(root, f"/dev/{node}", readonly=False)
    os.makedirs(inside(root, "dev/shm"), exist_ok=True)
    # A private instance of pseudo-terminals: lesson 07's bus emulator serves the arm on a pty
    # (os.openpty), and the host's /dev/pts (other users' terminals) stays out of sight.
    os.makedirs(inside(root, "dev/pts"), exist_ok=True)
    try:
        mount("devpts", inside(root, "dev/pts"), "devpts", MS_NOSUID | MS_NOEXEC, "newinstance,ptmxmode=0666,mode=0620")
        os.symlink("pts/ptmx", inside(root, "dev/ptmx"))
    except OSError as e:  # a kernel that refuses devpts here: the emulator then says it has no pty
        print(f"sandbox: no private pseudo-terminals ({e})", file=sys.stderr)
    mount("tmpfs", inside(root, "dev/shm"), "tmpfs", MS_NOSUID | MS_NODEV, f"mode=1777,size={lim['tmp']}")
    for name, target in (("fd", "/proc/self/fd"), ("stdin", "/proc/self/fd/0"), ("stdout", "/proc/self/fd/1"),
                         ("stderr", "/proc/self/fd/2")):
        os.symlink(target, inside(root, f"dev/{name}"))
    work = cfg["workdir"]
    os.makedirs(inside(root, work), exist_ok=True)
    mount(work, inside(root, work), None, MS_BIND)
    mount(None, inside(root, work), None, MS_REMOUNT | MS_BIND | MS_NOSUID | MS_NODEV)
    ip = next((p for p in ("/usr/sbin/ip", "/sbin/ip", "/usr/bin/ip", "/bin/ip") if os.path.exists(p)), "ip")
    subprocess.run([ip, "link", "set", "lo", "up"], check=True)
    os.chroot(root)
    os.chdir(work)
    for res, value in ((resource.RLIMIT_AS, lim["as"]), (resource.RLIMIT_FSIZE, lim["fsize"]),
                       (resource.RLIMIT_CORE, 0)):
        resource.setrlimit(res, (value, value))
    resource.setrlimit(resource.RLIMIT_CPU, (lim["cpu"], lim["cpu"] + 5))
    if cfg["uid"] is not None:
        os.setgroups([])
        os.setgid(cfg["gid"])
        os.setuid(cfg["uid"])
    libc.prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0)


def main():
    with open(sys.argv[1]) as f:
        cfg = json.load(f)
    enter(cfg)
    os.execve(cfg["argv"][0], cfg["argv"], cfg["env"])


if __name__ == "__main__":
    try:
        main()
    except Exception as e:  # noqa: BLE001 - anything that stops the sandbox from being made
        print(f"sandbox: {type(e).__name__}: {e}", file=sys.stderr)
        os._exit(125)
