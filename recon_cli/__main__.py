from recon_cli.cli import entry

entry()
