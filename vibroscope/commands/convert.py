"""``vibroscope convert IN OUT.mcap``: CSV, MATLAB .mat or UFF 58 to an MCAP log."""

from __future__ import annotations


def add_parser(sub) -> None:
    """Register the ``convert`` sub-command."""
    p = sub.add_parser("convert", help="convert CSV / .mat / UFF 58 data to an MCAP log")
    p.add_argument("input", metavar="IN", help="input file (.csv, .txt, .mat, .uff)")
    p.add_argument("output", metavar="OUT.mcap", help="output MCAP file")
    p.add_argument("--fs", type=float, help="sampling rate in Hz (needed without a time column / fs variable)")
    p.add_argument("--channels", help="comma-separated channel names")
    p.add_argument("--units", help="comma-separated units (one for all, or one per channel)")
    p.add_argument("--columns", help="CSV columns to read, 0-based, e.g. 0-17 or 0,2,5-7")
    p.add_argument("--kind", choices=("auto", "acceleration", "other"), default="auto",
                   help="'acceleration': write every channel as sensor_msgs/msg/Imu linear_acceleration.x; "
                        "'auto': those with unit m/s^2")
    p.add_argument("--topic-prefix", default="/vibroscope", help="topic prefix (default /vibroscope)")
    p.add_argument("--progress", action="store_true", help="show a progress bar")
    p.set_defaults(func=run)


def run(args) -> int:
    """Convert; returns the exit status."""
    from vibroscope.io.convert import convert_to_mcap

    path, sig = convert_to_mcap(
        args.input, args.output, fs=args.fs, columns=args.columns, names=args.channels, units=args.units,
        kind=args.kind, topic_prefix=args.topic_prefix, progress=args.progress,
    )
    print(f"wrote {path}: {sig.n_channels} channels x {sig.n_samples} samples at {sig.fs:g} Hz")
    for c, u in zip(sig.channels, sig.units):
        print(f"  {c} [{u}]")
    return 0
