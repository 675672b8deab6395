"""The 30-cell maze of Knox & Stone as a Gymnasium environment (INFORM paper, Sec. V-A; docs/protocol.md, "The maze").

    +--+--+--+--+--+--+
    | 0  1  2  3 S |G |        S = cell 4 = (row 0, col 4)
    +  +--+--+--+--+  +        G = cell 5 = (row 0, col 5)
    | 6|##| 7  8  9 10|
    +  +--+  +--+--+  +
    |11|##|12|##|##|13|
    +  +--+  +--+--+  +
    |14|##|15 16 17 18|
    +  +--+  +  +  +  +
    |19|##|20 21 22 23|
    +  +--+--+--+--+  +
    |24 25 26 27 28 29|
    +--+--+--+--+--+--+

Actions: 0 up, 1 down, 2 left, 3 right. A move into a wall, a blocked cell or the border leaves the agent
in place. Reward +1 on entering G, which terminates; 0 otherwise. Observations are one-hot over the 30 free cells.
The wall variant adds walls in column 5 between rows 1-2 and rows 2-3 (cell 13 becomes unreachable).

Importing this module registers:
    KnoxStoneMaze-v0           the plain maze, start S           (shortest path 19)
    KnoxStoneMazeWall-v0       the wall variant, start S         (shortest path 25)
    KnoxStoneMazeStartSet-v0   the plain maze, start drawn from START_SET each reset
    KnoxStoneMazeAnyStart-v0   the plain maze, start drawn from all 29 cells but G each reset (a day that covers
                               the maze)

    import gymnasium as gym, gridworld_env
    env = gym.make("KnoxStoneMaze-v0", render_mode="ansi")
"""

import gymnasium as gym
import numpy as np
from gymnasium import spaces

ROWS = 6
COLS = 6
BLOCKED = frozenset({(1, 1), (2, 1), (3, 1), (4, 1), (2, 3), (2, 4)})
# Walls between two free cells, as pairs of (row, col); read off the drawing in the module docstring.
PLAIN_WALLS = frozenset(
    frozenset(pair)
    for pair in [
        ((0, 4), (0, 5)),  # between S and G
        ((0, 2), (1, 2)),
        ((0, 3), (1, 3)),
        ((0, 4), (1, 4)),
        ((4, 2), (5, 2)),
        ((4, 3), (5, 3)),
        ((4, 4), (5, 4)),
    ]
)
WALL_VARIANT_WALLS = PLAIN_WALLS | {frozenset({(1, 5), (2, 5)}), frozenset({(2, 5), (3, 5)})}
VARIANT_WALLS = {"plain": PLAIN_WALLS, "wall": WALL_VARIANT_WALLS}

CELLS = [(r, c) for r in range(ROWS) for c in range(COLS) if (r, c) not in BLOCKED]  # cell index -> (row, col)
CELL_INDEX = {rc: i for i, rc in enumerate(CELLS)}
N_CELLS = len(CELLS)
N_ACTIONS = 4
START = 4
GOAL = 5
START_SET = (7, 8, 9, 12, 15, 16, 17, 20, 21, 22)  # the authors' generalisation starts
ANY_START = tuple(cell for cell in range(N_CELLS) if cell != GOAL)  # every cell but G
MOVES = ((-1, 0), (1, 0), (0, -1), (0, 1))  # up, down, left, right
ACTION_NAMES = ("up", "down", "left", "right")


def transition_table(variant: str = "plain") -> np.ndarray:
    """next_cell[s, a] of the deterministic move from cell s with action a."""
    walls = VARIANT_WALLS[variant]
    next_cell = np.empty((N_CELLS, N_ACTIONS), dtype=np.int64)
    for s, (r, c) in enumerate(CELLS):
        for a, (dr, dc) in enumerate(MOVES):
            target = (r + dr, c + dc)
            blocked = target not in CELL_INDEX or frozenset({(r, c), target}) in walls
            next_cell[s, a] = s if blocked else CELL_INDEX[target]
    return next_cell


def optimal_q(variant: str = "plain", gamma: float = 0.99, tol: float = 1e-10) -> np.ndarray:
    """Exact Q*(s, a) by value iteration, shape (30, 4). The goal is terminal, so V*(G) = 0."""
    next_cell = transition_table(variant)
    reward = (next_cell == GOAL).astype(np.float64)
    not_done = 1.0 - reward
    q = np.zeros((N_CELLS, N_ACTIONS))
    while True:
        new_q = reward + gamma * not_done * q.max(axis=1)[next_cell]
        if np.abs(new_q - q).max() < tol:
            return new_q
        q = new_q


ARROWS = "^v<>"  # up, down, left, right, as drawn by draw_maze


def draw_maze(variant: str = "plain", agent: int | None = None, arrows: dict[int, int] | None = None) -> str:
    """The maze as text (the env's ansi render), three characters a cell: S the start (always shown), A the agent,
    G the goal, ### blocked cells; `arrows` maps cells to actions drawn as ^ v < > (the agent on S moving left: SA<)."""
    walls = VARIANT_WALLS[variant]
    arrows = arrows or {}

    def open_between(a, b):
        return a in CELL_INDEX and b in CELL_INDEX and frozenset({a, b}) not in walls

    def content(i):
        if i is None:
            return "###"
        who = "A" if i == agent else "G" if i == GOAL else " "
        return ("S" if i == START else " ") + who + (ARROWS[arrows[i]] if i in arrows else " ")

    lines = ["+---" * COLS + "+"]
    for r in range(ROWS):
        row = "|"
        for c in range(COLS):
            row += content(CELL_INDEX.get((r, c)))
            row += " " if c + 1 < COLS and open_between((r, c), (r, c + 1)) else "|"
        lines.append(row)
        lines.append("+" + "+".join("   " if open_between((r, c), (r + 1, c)) else "---" for c in range(COLS)) + "+")
    return "\n".join(lines) + "\n"


def greedy_episode_length(policy: np.ndarray, variant: str = "plain", start: int = START, max_steps: int = 200) -> int:
    """Steps a deterministic table policy (one action per cell) takes from `start` to G; max_steps if it never does."""
    next_cell = transition_table(variant)
    s = start
    for t in range(1, max_steps + 1):
        s = next_cell[s, policy[s]]
        if s == GOAL:
            return t
    return max_steps


def draw_greedy_path(policy: np.ndarray, variant: str) -> str:
    """A greedy table policy's path from S drawn on the maze, and where it ends."""
    next_cell = transition_table(variant)
    cell, arrows = START, {}
    while cell != GOAL and cell not in arrows:  # a deterministic path either ends in G or loops
        arrows[cell] = int(policy[cell])
        cell = int(next_cell[cell, policy[cell]])
    ending = f"reaches G in {len(arrows)} steps" if cell == GOAL else "never reaches G: it loops"
    return draw_maze(variant, agent=START, arrows=arrows) + ending


class KnoxStoneMazeEnv(gym.Env):
    """The maze. `variant` is "plain" or "wall"; `start_cells` lists the cells a reset may start from."""

    metadata = {"render_modes": ["ansi", "rgb_array"], "render_fps": 4}

    def __init__(self, variant: str = "plain", start_cells: tuple[int, ...] = (START,), render_mode: str | None = None):
        if variant not in VARIANT_WALLS:
            raise ValueError(f"unknown maze variant {variant!r}; choose one of {sorted(VARIANT_WALLS)}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"unknown render_mode {render_mode!r}; choose one of {self.metadata['render_modes']}")
        self.variant = variant
        self.start_cells = tuple(start_cells)
        self.render_mode = render_mode
        self.next_cell = transition_table(variant)
        self.observation_space = spaces.Box(0.0, 1.0, shape=(N_CELLS,), dtype=np.float32)
        self.action_space = spaces.Discrete(N_ACTIONS)
        self.cell = self.start_cells[0]

    def _obs(self) -> np.ndarray:
        obs = np.zeros(N_CELLS, dtype=np.float32)
        obs[self.cell] = 1.0
        return obs

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if options is not None and "start_cell" in options:  # evaluation visits every start cell once
            self.cell = int(options["start_cell"])
        else:
            self.cell = self.start_cells[self.np_random.integers(len(self.start_cells))]
        return self._obs(), {"cell": self.cell}

    def step(self, action):
        self.cell = int(self.next_cell[self.cell, int(action)])
        terminated = self.cell == GOAL
        return self._obs(), float(terminated), terminated, False, {"cell": self.cell}

    def render(self):
        if self.render_mode == "ansi":
            return self._render_text()
        if self.render_mode == "rgb_array":
            return self._render_rgb()
        return None

    def _render_text(self) -> str:
        return draw_maze(self.variant, agent=self.cell)

    def _render_rgb(self, cell_px: int = 32) -> np.ndarray:
        img = np.full((ROWS * cell_px, COLS * cell_px, 3), 255, dtype=np.uint8)
        for r, c in BLOCKED:
            img[r * cell_px : (r + 1) * cell_px, c * cell_px : (c + 1) * cell_px] = 60
        colours = {GOAL: (40, 170, 60), self.cell: (200, 40, 40)}
        for i, colour in colours.items():
            r, c = CELLS[i]
            pad = cell_px // 5
            img[r * cell_px + pad : (r + 1) * cell_px - pad, c * cell_px + pad : (c + 1) * cell_px - pad] = colour
        walls = VARIANT_WALLS[self.variant]
        for wall in walls:
            (r1, c1), (r2, c2) = sorted(wall)
            if r1 == r2:  # vertical wall on the right of (r1, c1)
                x = c2 * cell_px
                img[r1 * cell_px : (r1 + 1) * cell_px, x - 1 : x + 2] = 0
            else:  # horizontal wall below (r1, c1)
                y = r2 * cell_px
                img[y - 1 : y + 2, c1 * cell_px : (c1 + 1) * cell_px] = 0
        img[[0, 1, -2, -1], :] = 0
        img[:, [0, 1, -2, -1]] = 0
        return img


ENV_IDS = {  # every id this module registers, with its constructor arguments
    "KnoxStoneMaze-v0": {"variant": "plain"},
    "KnoxStoneMazeWall-v0": {"variant": "wall"},
    "KnoxStoneMazeStartSet-v0": {"variant": "plain", "start_cells": START_SET},
    "KnoxStoneMazeAnyStart-v0": {"variant": "plain", "start_cells": ANY_START},
}


def register_envs() -> None:
    for env_id, kwargs in ENV_IDS.items():
        if env_id not in gym.registry:
            gym.register(env_id, entry_point=KnoxStoneMazeEnv, kwargs=kwargs, max_episode_steps=200)


register_envs()
