from dtwin.cli import main

main()
