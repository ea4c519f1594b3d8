"""The `mlaa-stream` command: a group whose default command is the filter itself.

Exit codes: 0 success; 1 some inputs failed (others were processed); 2 usage error;
3 no OpenCL device; 130 interrupted; 141 standard output closed by its reader (-o - | head).
"""
from __future__ import annotations

import click

from mlaa_stream.cli import devices_cmd, filter_cmd
from mlaa_stream.cli import overlay_cmd
from mlaa_stream.cli import bench_cmd, compare_cmd, scenes_cmd

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_NO_DEVICE, EXIT_INTERRUPTED = 0, 1, 2, 3, 130


class DefaultGroup(click.Group):
    """`mlaa-stream IN -o OUT` runs the `filter` command; `mlaa-stream devices` a subcommand."""

    default_command = "filter"

    def parse_args(self, ctx, args):
        if args and args[0] not in self.commands and args[0] not in ("--help", "-h", "--version"):
            args = [self.default_command, *args]
        return super().parse_args(ctx, args)


@click.group(cls=DefaultGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="mlaa-stream")
def main() -> None:
    """Remove jaggies from images, frame folders and video with morphological antialiasing.

    \b
    mlaa-stream INPUT -o OUTPUT      filter an image, a folder of images or a video
    mlaa-stream devices              list OpenCL devices
    mlaa-stream COMMAND --help       help for one command
    """


main.add_command(filter_cmd.filter_command)
main.add_command(devices_cmd.devices_command)
main.add_command(overlay_cmd.overlay_command)
main.add_command(scenes_cmd.scenes_command)
main.add_command(bench_cmd.bench_command)
main.add_command(compare_cmd.compare_command)

if __name__ == "__main__":   # python -m mlaa_stream.cli.main, as the mlaa-stream script runs it
    main()
