"""What the Prefect UI shows of the data: preview images of pairs (A | B | mask samples) and the
markdown of release and pair artifacts, and the small read-only HTTP server (`siteline previews
serve`, started by `make serve`) that lets the browser load them and the releases' montages."""
