"""The ``grip-force`` command's own behaviour, apart from any one subcommand."""
import json
import subprocess
import sys
import textwrap

#: A subcommand that, like a run with Fast DDS in the process, has C-level output on file
#: descriptor 1 (a line ``ros2 lifecycle get`` can print), a child
#: process that inherits it, and then prints its JSON answer.
NOISY_COMMAND = textwrap.dedent('''
    import os, subprocess, sys, types
    import grip_force_ros.lab.cli as cli

    def run(args):
        os.write(1, b'\\x1b[37;1m2026-11-27 01:02:03.456 [RTPS_TRANSPORT_SHM Error] '
                    b'Failed init_port fastrtps_port7411: open_and_lock_file failed\\x1b[m\\n')
        subprocess.run(['echo', 'a child on the inherited stdout'], check=True)
        print('{"answer": %d}' % (42 if args.json else 0))
        return 0

    module = types.ModuleType('grip_force_ros.lab.cli.noisy')
    module.HELP = 'test only'
    module.add_arguments = lambda p: p.add_argument('--json', action='store_true')
    module.run = run
    sys.modules[module.__name__] = module
    cli.COMMANDS['noisy'] = 'noisy'
    sys.exit(cli.main(sys.argv[1:]))
''')


def _noisy(*args):
    return subprocess.run([sys.executable, '-c', NOISY_COMMAND, 'noisy', *args],
                          capture_output=True, text=True, timeout=60)


def test_json_output_holds_only_the_answer_when_the_process_writes_to_its_stdout():
    got = _noisy('--json')
    assert got.returncode == 0, got.stderr
    assert json.loads(got.stdout) == {'answer': 42}
    assert 'RTPS_TRANSPORT_SHM Error' in got.stderr
    assert 'a child on the inherited stdout' in got.stderr


def test_without_json_the_output_is_left_where_it_was_written():
    got = _noisy()
    assert got.returncode == 0, got.stderr
    assert got.stdout.splitlines() == [
        '\x1b[37;1m2026-11-27 01:02:03.456 [RTPS_TRANSPORT_SHM Error] Failed init_port '
        'fastrtps_port7411: open_and_lock_file failed\x1b[m',
        'a child on the inherited stdout', '{"answer": 0}']
