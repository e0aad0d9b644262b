"""What machine a tools/ script ran on, for the reports it writes; the environment of
the child processes that time compiles."""
import os
import platform
import subprocess

#: the environment variable that names Taichi's offline kernel cache directory
KERNEL_CACHE_ENV = "TI_OFFLINE_CACHE_FILE_PATH"


def kernel_cache_env(cache: str, **extra: str) -> dict:
    """This process's environment for a child process whose Taichi keeps its compiled
    kernels in directory ``cache`` (an empty one: every kernel compiles, as on a fresh
    machine or in CI), with the variables ``extra`` set too."""
    return dict(os.environ, **{KERNEL_CACHE_ENV: cache}, **extra)


def untimed_pass(sim, run) -> None:
    """``run(sim)`` once, then put ``sim`` back where it was (Simulation.checkpoint and
    restore: the same bits as never having run). Taichi compiles a kernel the first
    time it runs, some only once impacts start: a timed window that repeats the pass
    compiles nothing."""
    start = sim.checkpoint()
    run(sim)
    sim.restore(start)


def cpu_name():
    """CPU model from /proc/cpuinfo (Linux), else what platform knows."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def gpu_name():
    """NVIDIA GPU name from nvidia-smi, or None."""
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
                             capture_output=True, text=True, timeout=10)
        return out.stdout.strip().splitlines()[0] if out.returncode == 0 else None
    except Exception:
        return None


def hardware(arch: str) -> str:
    """What a run on ``arch`` ran on, for a report: the CPU model on "cpu", else the GPU
    (nvidia-smi's name, or the arch)."""
    return cpu_name() if arch == "cpu" else (gpu_name() or arch)


SECTION_BEGIN = "<!-- begin {} -->"
SECTION_END = "<!-- end {} -->"


def kept_sections(text: str) -> str:
    """The marked sections of a report (``<!-- begin NAME -->`` ... ``<!-- end NAME -->``,
    written by write_section), so that a tool rewriting the rest keeps them."""
    out, keep = [], False
    for line in text.splitlines():
        if line.startswith("<!-- begin "):
            keep = True
        if keep:
            out.append(line)
        if line.startswith("<!-- end "):
            keep = False
            out.append("")
    return "\n".join(out)


def write_section(path: str, name: str, markdown: str) -> None:
    """Put ``markdown`` into the section NAME of the report at ``path`` (replacing the
    section if there is one, else appending it)."""
    try:
        with open(path) as fh:
            text = fh.read()
    except FileNotFoundError:
        text = ""
    begin, end = SECTION_BEGIN.format(name), SECTION_END.format(name)
    block = f"{begin}\n{markdown.strip()}\n{end}"
    if begin in text and end in text:
        head, rest = text.split(begin, 1)
        text = head + block + rest.split(end, 1)[1]
    else:
        text = text.rstrip() + "\n\n" + block + "\n"
    with open(path, "w") as fh:
        fh.write(text)


def publish(text: str, section: str, write: bool) -> None:
    """Print a tool's report; with ``write``, also put it into docs/bench.md's section."""
    import os
    print(text)
    if write:
        write_section(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "docs",
                                   "bench.md"), section, text)


def tuning_args(items, ap) -> dict:
    """--tuning NAME=VALUE items as Tuning.with_ keywords (values as Python literals:
    numbers and True/False, else strings); an error naming a bad item."""
    import ast
    from taichi_spheres.config import Tuning
    out = {}
    for item in items or ():
        name, sep, text = item.partition("=")
        if not sep:
            ap.error(f"--tuning {item!r}: write NAME=VALUE")
        try:
            out[name] = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            out[name] = text
    try:
        Tuning().with_(**out)
    except ValueError as exc:
        ap.error(f"--tuning: {exc}")
    return out


#: the contact solver's former defaults (CHANGELOG): plain sweeps (no over-relaxation), at
#: most 100 velocity (as now) and 100 position sweeps, the full caps in every step, no
#: substeps, no position extension (Tuning.with_ keywords); the tools' "former defaults"
#: variants run them (with today's position pass, which stops on the overlap it meets)
FORMER_DEFAULTS = dict(relaxation=1.0, position_iterations=100, substeps=False,
                       step_scaled_sweeps=False, position_extension=0)


def step_fraction_option(step_fraction) -> dict:
    """Simulation keywords for ``step_fraction`` (None: none, the Simulation's default);
    ValueError unless it is a number in (0, 1] (simulation.check_step_fraction, the
    Simulation's own check, run before a tool's first run)."""
    if step_fraction is None:
        return {}
    from taichi_spheres.simulation import check_step_fraction
    return {"step_fraction": check_step_fraction(step_fraction)}


def step_fraction_arg(step_fraction, ap) -> dict:
    """step_fraction_option of a --step-fraction option, or the parser's error naming
    it."""
    try:
        return step_fraction_option(step_fraction)
    except ValueError as exc:
        ap.error(f"--step-fraction: {exc}")


def tuning_code(changes: dict) -> str:
    """Tuning.with_ keywords as the code that builds them: ``Tuning().with_(k=v, ...)``."""
    return "Tuning().with_(" + ", ".join(f"{k}={v!r}" for k, v in changes.items()) + ")"


def tuning_text(changes: dict) -> str:
    """Tuning.with_ keywords as blank-separated NAME=VALUE items (--tuning's form)."""
    return " ".join(f"{name}={value}" for name, value in changes.items())
