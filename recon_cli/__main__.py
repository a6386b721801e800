from recon_cli.cli import main

main()
