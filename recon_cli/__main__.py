from recon_cli.cli import run

run()
