from recon_cli.cli import entry

# the guard: Dask's LocalCluster (recon batch --cluster local) starts its worker processes
# with multiprocessing's "spawn", which imports the main module again
if __name__ == "__main__":
    entry()
