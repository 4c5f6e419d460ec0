"""Big stand-ins and oracles shared by more than one chapter (each in its own module).

Chapter packages import these by module (`from graders.oracles.bundle_adjust import ...`); an oracle
here never imports a chapter package.
"""
