from stochpend.cli import main

main()
