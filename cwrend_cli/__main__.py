"""``python -m cwrend_cli`` runs the command line."""

from cwrend_cli.cli import app

if __name__ == "__main__":
    app()
