from avard.daemon import cli


def test_no_command_prints_help_and_fails(capsys):
    assert cli.main([]) == 2
    assert "COMMAND" in capsys.readouterr().err


def test_import_does_not_touch_hardware():
    import avard.daemon  # noqa: F401  (the import itself is the test: no bus is opened)
    import avard.core  # noqa: F401
