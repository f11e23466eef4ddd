"""Generated at install time from proto/rayfarm.proto (setup.py); nothing is kept here."""
