"""The scene wing: the scene schema and its parser, its key table, where its mesh comes from and what
is checked against it, resource estimates and setup advice. Below: base ... physics."""
