"""``python3 -m markovmotion``: the ``markovmotion`` command line."""

from markovmotion.cli import main

if __name__ == "__main__":
    main()
