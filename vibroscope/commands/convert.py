"""``vibroscope convert IN OUT.mcap``: CSV, MATLAB .mat or UFF 58 to an MCAP log."""

from __future__ import annotations

import sys


def add_parser(sub) -> None:
    """Register the ``convert`` sub-command."""
    p = sub.add_parser(
        "convert", help="convert CSV / .mat / UFF 58 data to an MCAP log",
        description="Convert CSV / .mat / UFF 58 data to an MCAP log. Channels are chosen and labelled by name "
                    "in every format (CSV header names or c0, c1, ... without a header; .mat variable names, "
                    "acc[k] for the columns of a matrix acc; UFF 58 record names). Each channel's unit is stored "
                    "in the MCAP. The output is written under a temporary name and renamed when complete.",
    )
    p.add_argument("input", metavar="IN", help="input file (.csv, .txt, .tsv, .mat, .uff, .unv)")
    p.add_argument("output", metavar="OUT.mcap", help="output MCAP file (not the input)")
    p.add_argument("--fs", type=float,
                   help="sampling rate in Hz (needed for a CSV without a time column / a .mat without an fs variable)")
    p.add_argument("--channels", help="comma-separated channel names to convert, in this order (default: all)")
    p.add_argument("--units",
                   help="units: name=unit pairs (force=N,acc=m/s^2), one unit for all channels, or one per "
                        "selected channel in the --channels order")
    p.add_argument("--columns", help="CSV columns to read, 0-based, e.g. 0-17 or 0,2,5-7")
    p.add_argument("--time-column",
                   help="CSV column of sample times in s, by index or header name (default: a header column "
                        "named t, time, time_s or 'time [s]', unless --columns lists it as data; with --fs too, they must agree)")
    p.add_argument("--kind", choices=("auto", "acceleration", "other"), default="auto",
                   help="'acceleration': write every channel as sensor_msgs/msg/Imu linear_acceleration.x; "
                        "'auto': those with unit m/s^2")
    p.add_argument("--topic-prefix", default="/vibroscope", help="topic prefix (default /vibroscope)")
    p.add_argument("--topic", action="append", metavar="NAME=CHANNEL[:TYPE[:FIELD]]", dest="topics",
                   help="write CHANNEL on topic NAME as TYPE: json, wrench (geometry_msgs/WrenchStamped, field "
                        "wrench.force.x) or imu (sensor_msgs/Imu, field linear_acceleration.x); FIELD another "
                        "number field of the type (linear_acceleration.z, wrench.torque.y) or the JSON field name. "
                        "Without TYPE: wrench for a channel in N, imu in m/s^2, else json. Repeat for each channel; "
                        "channels may share a topic. E.g. --topic /shaker/force=Force:wrench --topic /imu/s02=s02:imu")
    p.add_argument("--progress", action="store_true", help="show a progress bar")
    p.set_defaults(func=run)


def run(args) -> int:
    """Convert; returns the exit status (1 for an input or option the converter cannot use, said in
    one line, as every command's errors; 2 stays argparse's usage errors)."""
    from vibroscope.commands._outputs import check_outputs
    from vibroscope.io.convert import convert_to_mcap

    # before any work: OUT is not the input, not a link, FIFO or device, nor a file vibroscope did not write
    check_outputs({"OUT": args.output}, {"IN": args.input})
    tc = args.time_column
    if tc is not None and tc.strip().lstrip("-").isascii() and tc.strip().lstrip("-").isdigit():
        tc = int(tc)
    try:
        path, sig = convert_to_mcap(
            args.input, args.output, fs=args.fs, columns=args.columns, channels=args.channels, units=args.units,
            time_column=tc, kind=args.kind, topic_prefix=args.topic_prefix, topics=args.topics,
            progress=args.progress,
        )
    except ValueError as exc:
        if getattr(args, "debug", False):
            raise
        print(f"vibroscope convert: error: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {path}: {sig.n_channels} channels x {sig.n_samples} samples at {sig.fs:g} Hz")
    for c, u in zip(sig.channels, sig.units):
        print(f"  {c} [{u}]")
    return 0
