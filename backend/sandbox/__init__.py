"""The upload sandbox: untrusted files parsed in limited child processes (`manager`
starts and feeds them, `child` is their program, `tasks` what they can be asked to do)."""
