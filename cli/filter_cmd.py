"""`mlaa-stream INPUT -o OUTPUT` -- placeholder, owned by the streaming work."""
import click


@click.command("filter")
@click.argument("input_path")
@click.option("-o", "--output", required=True)
def filter_command(input_path, output):
    """Filter an image, a folder of images or a video."""
    raise click.ClickException("not implemented yet")
